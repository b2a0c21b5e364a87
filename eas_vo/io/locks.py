"""The writer's lock of an output folder: one eas-vo process writes it, and a dead writer's
lock and leftovers are recognised by its process id and start time."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

from eas_vo.errors import EasVoError


def acquire_lock(lock: Path, out: Path) -> None:
    """Take `lock`: it appears whole, with this process's pid and start time already in it (a
    file of its own hard-linked to the lock's name), so a writer killed at any moment never
    leaves an empty lock that others must wait out."""
    mine = lock.with_name(f"{lock.name}.{os.getpid()}")
    mine.write_text(f"{os.getpid()} {_started(os.getpid()) or ''}\n")
    try:
        for _ in range(2):
            try:
                _link_or_create(mine, lock)
                return
            except FileExistsError:
                if _lock_is_held(lock):
                    raise EasVoError(
                        f"{out} is being written by another eas-vo process (pid {_lock_owner(lock)[0] or '?'}); "
                        "wait for it or choose another --out"
                    ) from None
                lock.unlink(missing_ok=True)  # its writer is gone: a crash left it, and maybe a staging folder
                _remove_leftovers(out)
        raise EasVoError(f"{out}: could not take its lock {lock}")
    finally:
        mine.unlink(missing_ok=True)


def _link_or_create(mine: Path, lock: Path) -> None:
    """`lock` made a second name of `mine`; FileExistsError if it exists. On a file system
    without hard links, created and then written (a kill in between leaves it empty)."""
    try:
        os.link(mine, lock)
    except FileExistsError:
        raise
    except OSError:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        with os.fdopen(fd, "w") as fh:
            fh.write(mine.read_text())


def _remove_leftovers(out: Path) -> None:
    """Staging folders and lock files of writers that are gone."""
    for stale in [*out.parent.glob(f".{out.name}.*.tmp"), *out.parent.glob(f".{out.name}.lock.*")]:
        pid = stale.name.removesuffix(".tmp").rsplit(".", 1)[-1]
        if pid.isdigit() and process_alive(int(pid)):
            continue
        if stale.is_dir():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            stale.unlink(missing_ok=True)


def _lock_owner(lock: Path) -> tuple[int, str | None]:
    """(pid, process start time or None) written in a lock; pid 0 if it holds none yet."""
    try:
        fields = lock.read_text().split()
        return int(fields[0]) if fields else 0, fields[1] if len(fields) > 1 else None
    except (OSError, ValueError):
        return 0, None


def _lock_is_held(lock: Path) -> bool:
    """A lock is held while its process lives (the same process: its pid and, where the system
    tells it, its start time); one without a pid yet (being written, or a crash between
    creating and writing it), or without the start time the system gives (not written by
    eas-vo), for 10 s after it was made."""
    pid, started = _lock_owner(lock)
    if pid and process_alive(pid):
        now = _started(pid)
        if now is None or started == now:
            return True
        if started is not None:  # the pid lives, but it is another process now
            return False
    elif pid:
        return False
    try:  # no pid, or a pid without the start time this system gives: trusted only while young
        return time.time() - lock.stat().st_mtime < 10.0
    except OSError:
        return False  # gone meanwhile: try again


def _started(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot, Linux /proc), or None if unknown:
    a pid reused by another process has another start time."""
    fields = _proc_stat(pid)
    return fields[19] if fields and len(fields) > 19 else None


def _proc_stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command name (state first), or None off Linux or
    once the process is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2 :].split()
    except (OSError, ValueError):
        return None


def process_alive(pid: int) -> bool:
    """Whether process `pid` runs: it exists and (where /proc tells) is not a zombie, as a
    killed writer stays until its new parent reaps it (in containers, maybe never)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    fields = _proc_stat(pid)
    return not fields or fields[0] != "Z"
