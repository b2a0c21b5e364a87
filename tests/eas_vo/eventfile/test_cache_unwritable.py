"""A cache folder that cannot be written (a read-only file system here, as mkstemp reports it)
costs speed, not the run: the events are read into memory with one notice per folder."""

import errno
import logging
import tempfile
from pathlib import Path

import numpy as np
import pytest

from eas_vo.errors import DataError
from helpers import load_event_file, random_events


@pytest.fixture
def read_only_cache(tmp_path, monkeypatch):
    """A fresh cache folder on a read-only file system: neither its folders nor its files can be
    created (EROFS, naming the folder or the file)."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(cache))
    make, mkdir = tempfile.mkstemp, Path.mkdir

    def mkstemp(*args, dir=None, **kwargs):
        if dir is not None and str(dir).startswith(str(cache)):
            raise OSError(errno.EROFS, "Read-only file system", str(dir / "x.tmp"))
        return make(*args, dir=dir, **kwargs)

    def read_only_mkdir(self, *args, **kwargs):
        if str(self).startswith(str(cache)):
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return mkdir(self, *args, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(Path, "mkdir", read_only_mkdir)
    return cache


def test_events_are_read_into_memory_with_one_notice(read_only_cache, tmp_path, caplog):
    from eas_vo.eventfile.text import format_events

    caplog.set_level(logging.INFO, logger="eas_vo")
    events = random_events(2000, seed=8)
    path = tmp_path / "events.txt"
    path.write_bytes(format_events(events))
    for _ in range(2):
        loaded = load_event_file(path)
        np.testing.assert_array_equal(loaded["x"], events["x"])
    said = [(r.levelno, r.getMessage()) for r in caplog.records if r.name.startswith("eas_vo")]
    assert len(said) == 1 and said[0][0] == logging.WARNING, said
    assert said[0][1].startswith(
        f"the event cache folder {read_only_cache / 'events'} cannot be written "
        "(Read-only file system); events are read into memory"
    )
    assert not read_only_cache.exists()


@pytest.mark.parametrize("cache_writable", [True, False])
def test_a_source_that_cannot_be_read_is_still_an_error_naming_it(tmp_path, monkeypatch, request, cache_writable):
    from eas_vo.eventfile import load_event_text

    if not cache_writable:
        request.getfixturevalue("read_only_cache")
    where = str(tmp_path / "events.txt")

    def unreadable():
        raise PermissionError(errno.EACCES, "Permission denied", where)

    with pytest.raises(DataError, match=rf"^{where}: cannot read (or cache )?events \(Permission denied\)$"):
        load_event_text(unreadable, ("unreadable", cache_writable), where, 240, 180)
