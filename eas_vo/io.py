"""File I/O shared by datasets and the pipeline: numeric text tables, TUM trajectories,
atomic writes, folder names."""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError


def cache_dir() -> Path:
    """User cache folder: $EAS_VO_CACHE_DIR, else $XDG_CACHE_HOME/eas-vo, else ~/.cache/eas-vo."""
    env = os.environ.get("EAS_VO_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eas-vo"


# ----------------------------------------------------------------------------- atomic writes


def _umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside `path`; on success rename it over `path` with the mode a
    plain `open` would have given it (0666 less the umask), else delete it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
    with atomic_path(path) as tmp:
        tmp.write_text(text)



def slug(text: str) -> str:
    """A file-name-safe name for a dataset spec, path or label: its last path component with
    every run of characters other than letters, digits and `._=-` replaced by `-`."""
    return re.sub(r"[^A-Za-z0-9._=-]+", "-", Path(text.rstrip("/")).name or text).strip("-")


# ----------------------------------------------------------------------------- text tables


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A TUM trajectory `t tx ty tz qx qy qz qw` -> (t [s], p [m] (N, 3), q_xyzw (N, 4))."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns, found {rows.shape[1]}")
    return rows[:, 0], rows[:, 1:4], rows[:, 4:8]


def read_table(path: str | Path, ncols: int, what: str) -> np.ndarray:
    """A whitespace-separated numeric text file -> float64 array (N, ncols); see `parse_table`."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(path, f"cannot read: {exc.strerror or exc}") from None
    return parse_table(data, str(path), ncols, what)


def parse_table(data: bytes, where: str, ncols: int, what: str) -> np.ndarray:
    """Whitespace-separated numeric text -> float64 array (N, ncols).

    A fast C parse; on any irregularity a line-by-line scan names the first bad line.
    Lines starting with '#' are comments. `what` describes one row in messages.
    """
    if b"#" not in data:
        try:
            values = np.fromstring(data, sep=" ")  # text mode is supported, only binary mode is deprecated
        except ValueError:
            values = None
        if values is not None and values.size % ncols == 0 and np.isfinite(values).all():
            table = values.reshape(-1, ncols)
            if len(table) == _count_lines(data):
                return table
    return _parse_table_slow(where, data, ncols, what)


def _count_lines(data: bytes) -> int:
    n = data.count(b"\n")
    return n + 1 if data and not data.endswith(b"\n") else n


def _parse_table_slow(path: str, data: bytes, ncols: int, what: str) -> np.ndarray:
    rows = []
    for lineno, line in enumerate(data.split(b"\n"), start=1):
        text = line.strip()
        if not text or text.startswith(b"#"):
            continue
        parts = text.split()
        if len(parts) != ncols:
            raise DataError(path, f"expected {ncols} columns ({what}), found {len(parts)}", lineno)
        try:
            row = [float(p) for p in parts]
        except ValueError:
            raise DataError(path, f"not a number in {text[:60].decode(errors='replace')!r}", lineno) from None
        if not all(np.isfinite(row)):
            raise DataError(path, "NaN or infinite value", lineno)
        rows.append(row)
    return np.array(rows, dtype=float).reshape(-1, ncols)
