"""Numeric text tables, atomic writes, and output folders: one writer at a time, one whole
run (or a marked partial one) per folder, nothing left behind, also when two real processes
race into one folder."""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from eas_vo.errors import DataError, EasVoError
from eas_vo.io.atomic import atomic_file, atomic_path
from eas_vo.io.outputs import check_output_folder, output_folder
from eas_vo.io.tables import read_table


def test_read_table_skips_comments_and_blank_lines(tmp_path):
    path = tmp_path / "t.txt"
    path.write_text("# header\n1 2 3\n\n4 5 6\n")
    np.testing.assert_array_equal(read_table(path, 3, "a b c"), [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("text,line", [("1 2 3\n4 5\n", 2), ("1 2 3\n4 x 6\n", 2), ("1 2 inf\n", 1)])
def test_read_table_names_the_bad_line(tmp_path, text, line):
    path = tmp_path / "t.txt"
    path.write_text(text)
    with pytest.raises(DataError) as info:
        read_table(path, 3, "a b c")
    assert info.value.line == line


def test_atomic_path_leaves_the_old_file_on_failure(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert path.read_text() == "old" and list(tmp_path.iterdir()) == [path]


def test_atomic_file_replaces_on_success_and_leaves_the_old_file_on_failure(tmp_path):
    """atomic_file writes through an open temporary (never a truncating reopen): the new bytes
    replace the old file whole on success; on failure the old file stays and no temporary does."""
    import os

    path = tmp_path / "out.bin"
    path.write_bytes(b"old contents, longer than the new")
    with atomic_file(path) as fh:
        assert fh.tell() == 0 and os.fstat(fh.fileno()).st_size == 0  # a fresh, empty temporary
        fh.write(b"new")
    assert path.read_bytes() == b"new"
    with pytest.raises(RuntimeError):
        with atomic_file(path) as fh:
            fh.write(b"half")
            raise RuntimeError("interrupted")
    assert path.read_bytes() == b"new" and list(tmp_path.iterdir()) == [path]


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_files_written_atomically_get_the_users_umask(tmp_path, umask):
    import os
    import stat

    old = os.umask(umask)
    try:
        with atomic_path(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
        (tmp_path / "b.txt").write_text("x")  # what a plain open gives
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "a.txt").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o666 & ~umask


def test_a_failed_run_leaves_the_old_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    with output_folder(out) as staging:
        (staging / "metrics.json").write_text("old\n")
    with pytest.raises(RuntimeError):
        with output_folder(out, replace=True) as staging:
            (staging / "metrics.json").write_text("new\n")
            raise RuntimeError("the run failed")
    assert (out / "metrics.json").read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder, no lock


def test_an_interrupted_run_lands_whole_and_a_live_writer_excludes_others(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with output_folder(out) as staging:
            (staging / "frames.csv").write_text("partial\n")
            with pytest.raises(EasVoError, match=r"is being written by another eas-vo process \(pid \d+\)"):
                with output_folder(out):
                    pass
            raise KeyboardInterrupt
    assert (out / "frames.csv").read_text() == "partial\n"


def test_a_crashed_writers_lock_and_leftovers_are_taken_over(tmp_path):
    out = tmp_path / "out"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / ".out.lock").write_text(dead.stdout)
    (tmp_path / f".out.{dead.stdout.strip()}.tmp").mkdir()
    (tmp_path / f".out.lock.{dead.stdout.strip()}").write_text(dead.stdout)  # killed before its lock was linked
    with output_folder(out) as staging:
        (staging / "metrics.json").write_text("{}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_lock_appears_with_its_owner_already_in_it(tmp_path, monkeypatch):
    """A writer killed between making its lock and writing it would leave an empty lock that
    blocks every other writer for 10 s: the lock is a second name of a file written first."""
    import eas_vo.io.locks as io_module

    seen = []
    real_link = os.link

    def link(source, target):
        seen.append(Path(source).read_text())  # what the lock holds the moment it exists
        real_link(source, target)

    monkeypatch.setattr(io_module.os, "link", link)
    with output_folder(tmp_path / "out"):
        assert (tmp_path / ".out.lock").read_text() == seen[0]
        assert seen[0].split()[0] == str(os.getpid())
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".out.lock")) == [".out.lock"]


def test_a_folder_is_replaced_only_if_asked_and_only_if_eas_vo_wrote_it(tmp_path):
    """Class 5 (and the data loss it hid): a non-empty --out is refused without --overwrite,
    checked again under the lock (a writer that finished first is not silently replaced), and a
    folder of someone's other files is never replaced, --overwrite or not."""
    out = tmp_path / "out"
    with output_folder(out) as staging:
        (staging / "metrics.json").write_text("first\n")
    with pytest.raises(EasVoError, match="is not empty; choose another folder or add --overwrite"):
        with output_folder(out):
            pass
    with output_folder(out, replace=True) as staging:
        (staging / "metrics.json").write_text("second\n")
    assert (out / "metrics.json").read_text() == "second\n"
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    for replace in (False, True):
        with pytest.raises(EasVoError, match="holds thesis.tex, which eas-vo did not write|is not empty"):
            with output_folder(mine, replace=replace):
                pass
    assert (mine / "thesis.tex").read_text() == "years of work"


def test_a_file_added_to_an_eas_vo_folder_keeps_it_from_being_replaced(tmp_path):
    """The marker lists what eas-vo wrote; a user's notes (or ORB-SLAM2's trajectory) added to
    an export folder make --overwrite refuse it, naming the file."""
    out = tmp_path / "export"
    with output_folder(out) as staging:
        (staging / "rgb").mkdir()
        (staging / "rgb" / "0.png").write_bytes(b"png")
        (staging / "settings.yaml").write_text("%YAML:1.0\n")
    with output_folder(out, replace=True) as staging:  # its own files only: replaced
        (staging / "settings.yaml").write_text("%YAML:1.0\n")
    (out / "KeyFrameTrajectory.txt").write_text("1 0 0 0 0 0 0 1\n")
    with pytest.raises(EasVoError, match="holds KeyFrameTrajectory.txt, which eas-vo did not write"):
        with output_folder(out, replace=True):
            pass
    assert (out / "KeyFrameTrajectory.txt").exists()


def test_dot_dotdot_and_symlinks_name_the_folder_they_resolve_to(tmp_path, monkeypatch):
    target = tmp_path / "real"
    link = tmp_path / "link"
    target.mkdir()
    link.symlink_to(target)
    with output_folder(link) as staging:
        (staging / "metrics.json").write_text("{}\n")
    assert link.is_symlink() and (target / "metrics.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    with output_folder(".") as staging:
        (staging / "x.txt").write_text("x\n")
    assert (work / "x.txt").exists()
    with pytest.raises(EasVoError, match="is the root of the file system"):
        check_output_folder("/", replace=True)


def test_a_lock_left_by_a_pid_now_used_by_another_process_is_taken_over(tmp_path):
    out = tmp_path / "out"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / ".out.lock").write_text(f"{other.pid} 1\n")  # its pid, but not its start time
        with output_folder(out) as staging:
            (staging / "metrics.json").write_text("{}\n")
        (tmp_path / ".out.lock").write_text(f"{other.pid}\n")  # a bare pid (not eas-vo's): trusted 10 s
        os.utime(tmp_path / ".out.lock", (time.time() - 60, time.time() - 60))
        with output_folder(out, replace=True) as staging:
            (staging / "metrics.json").write_text("{}\n")
    finally:
        other.kill()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_run_refuses_to_write_over_its_own_dataset(sequence_copy):
    from helpers import mark_as_eas_vo_output, run_eas_vo

    mark_as_eas_vo_output(sequence_copy)  # as `eas-vo simulate` leaves it: an eas-vo output, yet a dataset
    done = run_eas_vo(
        "run", "--dataset", str(sequence_copy), "--duration", "0.5", "--out", str(sequence_copy), "--overwrite"
    )
    assert done.returncode == 1 and "holds the dataset" in done.stderr
    assert (sequence_copy / "events.txt").exists()


def run_into(folder: Path, dataset: Path, duration: str) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "eas_vo",
            "run",
            "--dataset",
            str(dataset),
            "--frontend",
            "original",
            "--duration",
            duration,
            "--out",
            str(folder),
            "--overwrite",
            "--quiet",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tempfile.gettempdir(),
    )


def test_ten_races_of_two_runs_into_one_folder_leave_one_whole_run(short_sequence, tmp_path):
    """Two runs of different lengths into one folder at once, 10 times: each folder then holds
    exactly one of them, every file agreeing (config, identity, metrics, frames.csv)."""
    env_ok = {0, 1}  # done, or refused because the other one held the folder
    for round_ in range(10):
        folder = tmp_path / f"race{round_}"
        runs = [run_into(folder, short_sequence, d) for d in ("0.5", "1.0")]
        codes = [p.wait(timeout=120) for p in runs]
        errors = [p.stderr.read() for p in runs]
        assert set(codes) <= env_ok and 0 in codes, (codes, errors)
        for code, err in zip(codes, errors):
            assert code == 0 or "is being written by another eas-vo process" in err, err
        config = (folder / "config.toml").read_text()
        metrics = json.loads((folder / "metrics.json").read_text())
        rows = (folder / "frames.csv").read_text().splitlines()
        assert json.loads((folder / "identity.json").read_text())["config"] == config
        assert len(rows) - 1 == metrics["frames"] and not metrics["partial"]
        duration = 0.5 if "duration_s = 0.5" in config else 1.0
        assert abs(metrics["frames"] - 20 * duration) <= 1, (duration, metrics["frames"])
        assert sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(f".race{round_}.")) == []


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="process states are read from Linux's /proc")
def test_a_lock_held_by_a_zombie_is_taken_over(tmp_path):
    """A writer killed while its parent does not reap it stays a zombie: it holds nothing."""
    import signal

    out = tmp_path / "out"
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        started = Path(f"/proc/{child.pid}/stat").read_text()
        (tmp_path / ".out.lock").write_text(f"{child.pid} {started[started.rindex(')') + 2 :].split()[19]}\n")
        os.kill(child.pid, signal.SIGKILL)
        deadline = time.monotonic() + 10
        while Path(f"/proc/{child.pid}/stat").read_text().split(") ")[1][0] != "Z" and time.monotonic() < deadline:
            time.sleep(0.01)  # not reaped (no wait() yet): a zombie
        with output_folder(out) as staging:
            (staging / "metrics.json").write_text("{}\n")
    finally:
        child.wait()
    assert (out / "metrics.json").exists()


def test_the_cache_is_listed_and_cleared_folder_by_folder(tmp_path, monkeypatch):
    """Sizes count every visible file below a cache folder, never what a link inside points
    to; each folder says what it holds (the latest words); a part that is itself a link to a
    folder elsewhere is listed, and never emptied (nor anything else, asked with it); clearing
    keeps hidden files (a write under way), the folders, the others and any link's target;
    every name is checked first."""
    from eas_vo.io.cache import CachePart, cache_folder, cache_usage, clear_cache

    cache = tmp_path / "cache"
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(cache))
    assert cache_usage() == {}
    events = cache_folder("events", "event caches, old words")
    assert cache_folder("events", "event caches") == events
    (events / "a.ev").write_bytes(b"x" * 100)
    (events / ".a.ev.123.tmp").write_bytes(b"w" * 30)  # a write under way
    outside = tmp_path / "precious.ev"
    outside.write_bytes(b"y" * 1000)
    (events / "link.ev").symlink_to(outside)
    (cache / "synthetic" / "default-1" / "images").mkdir(parents=True)
    (cache / "synthetic" / "default-1" / "images.txt").write_bytes(b"z" * 50)
    (cache / "synthetic" / "default-1" / "images" / "f.png").write_bytes(b"z" * 7)
    elsewhere = tmp_path / "other_disk" / "data"
    elsewhere.mkdir(parents=True)
    (elsewhere / "seq.zip").write_bytes(b"d" * 9)
    (cache / "data").symlink_to(elsewhere)
    assert cache_usage() == {
        "data": CachePart(1, 9, "", True),
        "events": CachePart(2, 100, "event caches"),
        "synthetic": CachePart(1, 57, ""),
    }
    with pytest.raises(EasVoError, match="cache 'bench': not in .*cache .there: data, events, synthetic"):
        clear_cache(["events", "bench"])
    assert cache_usage()["events"].entries == 2  # nothing removed
    with pytest.raises(
        EasVoError, match=rf"cache 'data': .*data is a link to {elsewhere}, which eas-vo does not empty"
    ):
        clear_cache(["events", "data"])
    assert cache_usage()["events"].entries == 2 and (elsewhere / "seq.zip").read_bytes() == b"d" * 9
    assert clear_cache(["events", "synthetic", "events"]) == {"events": 100, "synthetic": 57}
    assert cache_usage() == {
        "data": CachePart(1, 9, "", True),
        "events": CachePart(0, 0, "event caches"),
        "synthetic": CachePart(0, 0, ""),
    }
    assert (
        outside.read_bytes() == b"y" * 1000 and (events / ".a.ev.123.tmp").exists() and (elsewhere / "seq.zip").exists()
    )
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(outside))
    with pytest.raises(EasVoError, match="precious.ev: the cache folder .EAS_VO_CACHE_DIR. is not a folder"):
        cache_usage()
