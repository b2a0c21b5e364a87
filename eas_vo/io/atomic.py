"""Atomic writes: a file appears whole under its name or not at all, with the user's umask;
strict JSON text."""

from __future__ import annotations

import errno
import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from eas_vo.io.locks import process_alive


def current_umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: The errors of a write (a full disk or quota, a file too large, a read-only or forbidden place,
#: a failing device), whose OSError names no file when `write` or `close` raised it.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO})


def name_the_written(exc: BaseException, path: Path) -> None:
    """Give a write's OSError that names no file the `path` being written (the CLI's one line
    says "No space left on device (PATH)"); any other exception is left as it is."""
    if isinstance(exc, OSError) and exc.filename is None and exc.errno in WRITE_ERRNOS:
        exc.filename = str(path)


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside `path`, `.NAME.PID.RANDOM.tmp`; on success rename it over
    `path` with the mode a plain `open` would have given it (0666 less the umask), else delete
    it (a killed writer's is left: remove_stale_temporaries). A write's error names `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        name_the_written(exc, path)
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_file(path: str | Path):
    """An open binary file to write, renamed over `path` on success (atomic_path's temporary).

    The temporary is opened write-only without truncating it (it is empty): on ext4 an open
    that truncates makes the close write the whole file out, with the caller waiting
    (docs/speed.md, "The event parser and its cache")."""
    with atomic_path(path) as tmp, os.fdopen(os.open(tmp, os.O_WRONLY), "wb") as fh:
        yield fh


def remove_stale_temporaries(folder: Path, names: tuple[str, ...]) -> None:
    """Delete the temporary files atomic_path left in `folder` for the files `names` (glob
    patterns, e.g. `fig3_*.png`) when the process that wrote them is gone (killed mid-write):
    those of a live writer, and every other file, stay."""
    for name in names:
        for tmp in folder.glob(f".{name}.*.tmp"):
            pid = tmp.name.removesuffix(".tmp").rsplit(".", 2)[-2]
            if tmp.is_file() and not tmp.is_symlink() and not (pid.isdigit() and process_alive(int(pid))):
                tmp.unlink(missing_ok=True)


def json_text(obj) -> str:
    """Strict JSON (RFC 8259), indented: NaN and infinities, which it cannot hold, become null."""

    def finite(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: finite(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(v) for v in value]
        return value

    return json.dumps(finite(obj), indent=2, allow_nan=False) + "\n"


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write `text` to `path` atomically (atomic_path)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
