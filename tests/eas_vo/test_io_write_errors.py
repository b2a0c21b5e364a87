"""A write that fails (a full disk, here as `write` reports it: an OSError naming no file)
names the file or output folder being written, so the CLI's one line says where."""

import errno
from pathlib import Path

import pytest

from eas_vo.io.atomic import atomic_path, write_text_atomic
from eas_vo.io.outputs import output_folder
from helpers import one_line_failure


def _full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_an_atomic_write_that_fails_names_its_file_and_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(Path, "write_text", _full_disk)
    with pytest.raises(OSError) as info:
        write_text_atomic(tmp_path / "table.md", "| a |\n")
    assert info.value.filename == str(tmp_path / "table.md") and list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError), atomic_path(tmp_path / "x.txt"):  # other errors are left as they are
        raise ValueError("not a write")


def test_a_write_into_an_output_folder_that_fails_names_the_folder(tmp_path):
    with pytest.raises(OSError) as info, output_folder(tmp_path / "run") as staging:
        (staging / "frames.csv").write_text("index\n")
        _full_disk()
    assert info.value.filename == str(tmp_path / "run") and not (tmp_path / "run").exists()


def test_run_on_a_full_disk_is_one_line_naming_the_file(short_sequence, tmp_path, monkeypatch, capsys):
    write = Path.write_text

    def full_for_metrics(self, *args, **kwargs):
        if self.name.startswith(".metrics.json."):
            _full_disk()
        return write(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full_for_metrics)
    err = one_line_failure(
        ["run", "--dataset", str(short_sequence), "--duration", "0.2", "--out", str(tmp_path / "run"), "--quiet"],
        capsys,
    )
    assert err == f"eas-vo: error: No space left on device ({(tmp_path / 'run').resolve() / 'metrics.json'})\n"
    assert not (tmp_path / "run").exists()
