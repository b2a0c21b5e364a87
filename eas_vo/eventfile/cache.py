"""The binary event cache and its use.

Cache file: 24-byte header (8-byte magic, uint64 event count, uint64 checksum) + packed
EVENT_DTYPE records (13 B/event), named by a hash of what identifies the source (for a file:
device, inode, size, modification and change times in ns, and a hash of samples of its
content). Written atomically, read by memory-mapping it once its checksum (XXH3-64 of the
records, at memory speed: docs/speed.md, "The event parser and its cache") matched; a damaged
cache is rebuilt with a one-line notice.
A lenient build's warnings sidecar is part of it: missing or unreadable, both are rebuilt.
A cache folder that cannot be written (read-only, not the user's, full) costs speed, not the
run: the events are read into memory, with one notice per folder.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import logging
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import BinaryIO, Callable

import numpy as np

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile.convert import convert_text_to_cache
from eas_vo.io.atomic import atomic_file
from eas_vo.io.cache import cache_folder
from eas_vo.types import EVENT_DTYPE

logger = logging.getLogger(__name__)

CACHE_MAGIC = b"EASVOEV3"
HEADER_BYTES = 24
SAMPLE_BYTES = 1 << 16  # content sampled for a file's identity: its start, middle and end


def cache_key(*parts) -> str:
    """A cache file's name: the SHA-1 of `parts` (a source's identity and the reading options)."""
    return hashlib.sha1("|".join(map(str, parts)).encode()).hexdigest()


def file_identity(path: Path) -> tuple:
    """What makes a file's content unique for the cache: device, inode, size, modification and
    change times [ns] (a rewrite whose mtime was put back still changes the ctime), and a hash
    of 64 KiB at its start, middle and end (for file systems with coarse times)."""
    st = path.stat()
    sample = hashlib.sha1()
    with open(path, "rb") as fh:
        for offset in sorted({0, max(st.st_size // 2 - SAMPLE_BYTES // 2, 0), max(st.st_size - SAMPLE_BYTES, 0)}):
            fh.seek(offset)
            sample.update(fh.read(SAMPLE_BYTES))
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns, sample.hexdigest()[:16])


def records_checksum(payload) -> int:
    """XXH3-64 of `payload` (bytes-like: the packed records): a full-avalanche hash, so no
    pattern of damage cancels out (as two opposite bit flips did in a sum); memory speed."""
    import xxhash

    return xxhash.xxh3_64_intdigest(memoryview(payload).cast("B") if len(payload) else b"")


def cache_path(key: str) -> Path:
    """Where the cache of `key` lives: the cache folder's `events` part."""
    return cache_folder("events", "binary event caches; rebuilt from their source when next read") / f"{key}.ev"


def open_cache(path: Path) -> np.ndarray | None:
    """Memory-map a cache file whose header, size and checksum hold; None if it is absent. A
    damaged one (another format, a wrong size, a checksum that fails) is removed with a notice
    (logged), and None returned: the caller rebuilds it."""
    if not path.exists():
        return None
    try:
        with open(path, "rb") as fh:
            header = fh.read(HEADER_BYTES)
        count = int.from_bytes(header[8:16], "little") if len(header) == HEADER_BYTES else -1
        sound = header[:8] == CACHE_MAGIC and path.stat().st_size == HEADER_BYTES + count * EVENT_DTYPE.itemsize
        if sound and count > 0:
            payload = np.memmap(path, dtype=np.uint8, mode="r", offset=HEADER_BYTES)
            sound = records_checksum(payload) == int.from_bytes(header[16:24], "little")
    except OSError:
        sound = False
    if not sound:
        logger.info(f"the event cache {path} is damaged or of another version; rebuilding it")
        path.unlink(missing_ok=True)
        return None
    return _map_records(path, count)


def _map_records(path: Path, count: int) -> np.ndarray:
    if count == 0:
        return np.empty(0, EVENT_DTYPE)
    return np.memmap(path, dtype=EVENT_DTYPE, mode="r", offset=HEADER_BYTES, shape=(count,))


class _HashingWriter:
    """A binary file's `write`/`writelines` that also hash what they write (XXH3-64, streamed:
    the digest of all bytes written so far) and count its bytes."""

    def __init__(self, fh: BinaryIO):
        import xxhash

        self.fh, self.hash, self.bytes = fh, xxhash.xxh3_64(), 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        self.hash.update(view)
        self.bytes += len(view)
        return self.fh.write(view)

    def writelines(self, chunks) -> None:
        for data in chunks:
            self.write(data)


def build_cache(path: Path, fill: Callable[[BinaryIO], int], max_events: int = 0) -> np.ndarray:
    """Write a cache file atomically: `fill(out)` writes the records with `out.write` or
    `out.writelines` and returns their count. The checksum is taken as they are written (no
    second pass over the file), and the finished file is mapped without reading it again.

    `max_events` > 0 reserves the file's blocks up front (fewer, faster writes on most file
    systems); the file is cut to its real size at the end.
    """
    with atomic_file(path) as fh:
        if max_events > 0 and hasattr(os, "posix_fallocate"):
            try:
                os.posix_fallocate(fh.fileno(), 0, HEADER_BYTES + max_events * EVENT_DTYPE.itemsize)
            except OSError:
                pass  # no space to reserve (or no support): plain writes still work
        fh.write(CACHE_MAGIC + bytes(16))
        out = _HashingWriter(fh)
        count = int(fill(out))
        if out.bytes != count * EVENT_DTYPE.itemsize:
            raise AssertionError(f"{out.bytes} bytes of records written for {count} events")
        fh.truncate(HEADER_BYTES + out.bytes)
        checksum = out.hash.intdigest() if count else 0
        fh.seek(8)
        fh.write(count.to_bytes(8, "little") + checksum.to_bytes(8, "little"))
    return _map_records(path, count)


def write_behind(out: BinaryIO, blocks: Iterable[Callable[[], np.ndarray | list[np.ndarray]]]) -> int:
    """Write the EVENT_DTYPE records each of `blocks` returns (an array, or a list of arrays
    written one after the other) to `out`, in order; returns their count. Block k is checked and written on a worker thread while the caller's
    iterator reads block k+1: the readers' libraries hold the GIL, the compiled checks and
    the write release it. One block waits at most (memory: two blocks). An error raised by
    the iterator comes after block k's own, so the earliest bad event is the one named."""
    total, pending = 0, None
    with ThreadPoolExecutor(1) as worker:
        try:
            for block in blocks:
                if pending is not None:
                    total += pending.result()
                pending = worker.submit(_write_block, out, block)
        except BaseException:
            if pending is not None:
                pending.result()
            raise
        if pending is not None:
            total += pending.result()
    return total


def _write_block(out: BinaryIO, block: Callable[[], np.ndarray | list[np.ndarray]]) -> int:
    parts = block()
    parts = [parts] if isinstance(parts, np.ndarray) else parts
    out.writelines(events.data for events in parts)
    return sum(len(events) for events in parts)


#: What writing a cache file answers when its folder cannot take it: a read-only file system,
#: a folder not the user's to write, a full disk or quota.
UNWRITABLE = (errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOSPC, errno.EDQUOT)


def _cache_unwritable(exc: OSError, folder: Path) -> bool:
    """Whether `exc` came from writing a cache file in `folder` (naming the folder, a file in
    it, or nothing: a write), not from reading the source (which names the source)."""
    return exc.errno in UNWRITABLE and (
        exc.filename is None or folder in (Path(exc.filename), Path(exc.filename).parent)
    )


@functools.cache  # once per folder and reason
def _say_unwritable(folder: Path, reason: str) -> None:
    logger.warning(
        f"the event cache folder {folder} cannot be written ({reason}); events are read into "
        "memory, and again next time (EAS_VO_CACHE_DIR chooses another folder)"
    )


class _MemoryWriter:
    """The `write`/`writelines` of a cache file, into memory (a cache that cannot be written)."""

    def __init__(self):
        self.chunks: list[bytes] = []

    def write(self, data) -> int:
        self.chunks.append(bytes(memoryview(data).cast("B")))
        return len(self.chunks[-1])

    def writelines(self, chunks) -> None:
        for data in chunks:
            self.write(data)

    def events(self) -> np.ndarray:
        return np.frombuffer(b"".join(self.chunks), EVENT_DTYPE)


def write_cache(path: Path, events: np.ndarray) -> np.ndarray:
    """Cache an in-memory event array (e.g. decoded from a bag)."""

    def fill(fh):
        fh.write(np.ascontiguousarray(events, dtype=EVENT_DTYPE).tobytes())
        return len(events)

    return build_cache(path, fill)


def load_cached(
    key: str,
    lenient: bool,
    warnings: DataWarnings,
    fill: Callable[[BinaryIO, DataWarnings], int],
    where: str,
    max_events: int = 0,
) -> np.ndarray:
    """The event stream cached under `key`, built by `fill(out, warnings)` when absent.

    A clean stream has one cache whatever the mode. A lenient build that dropped data
    is cached apart, with its warnings beside it, so they are reported on every use
    and a strict read never gets it.
    """
    strict = cache_path(key)
    tolerant = strict.with_name(strict.stem + "-lenient.ev")
    for path in (strict, tolerant) if lenient else (strict,):
        cached = open_cache(path)
        if cached is None:
            continue
        if path is strict:
            return cached
        kept = _read_sidecar(path.with_suffix(".warnings"))
        if kept is not None:
            warnings.merge(kept)
            return cached
        logger.info(f"the warnings of the event cache {path} are missing or damaged; rebuilding it")
        path.unlink(missing_ok=True)
    local = DataWarnings()
    target = tolerant if lenient else strict
    try:
        events = build_cache(target, lambda out: fill(out, local), max_events)
    except OSError as exc:
        if not _cache_unwritable(exc, target.parent):
            raise DataError(where, f"cannot read or cache events ({exc.strerror or exc})") from None
        _say_unwritable(target.parent, exc.strerror or str(exc))
        local, memory = DataWarnings(), _MemoryWriter()
        try:
            fill(memory, local)
        except OSError as exc:
            raise DataError(where, f"cannot read events ({exc.strerror or exc})") from None
        warnings.merge(local)
        return memory.events()
    if local.counts:
        from eas_vo.io.atomic import write_text_atomic

        write_text_atomic(target.with_suffix(".warnings"), local.to_json())
    elif target is tolerant:
        os.replace(tolerant, strict)
        events = _map_records(strict, len(events))
    warnings.merge(local)
    return events


def _read_sidecar(path: Path) -> DataWarnings | None:
    """The warnings a lenient build wrote beside its cache, or None if missing or unreadable."""
    try:
        return DataWarnings.from_json(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None


def load_event_text(
    open_text: Callable[[], BinaryIO],
    identity: tuple,
    where: str,
    width: int,
    height: int,
    tolerance_s: float = 1e-6,
    lenient: bool = False,
    warnings: DataWarnings | None = None,
    text_size: int | None = None,
    origin_s: float = 0.0,
) -> np.ndarray:
    """Events of a text source (`t x y p` lines, `text_size` bytes if known), through the cache,
    their times after the clock origin `origin_s` (whole seconds: Dataset.clock_origin_ns)."""

    def fill(out, local):
        with open_text() as fh:
            return convert_text_to_cache(fh, where, out, width, height, tolerance_s, lenient, local, origin_s=origin_s)

    key = cache_key("text", *identity, width, height, tolerance_s, origin_s)
    size = text_size or 0  # a line is at least 8 bytes: at most size // 8 events
    return load_cached(
        key, lenient, warnings if warnings is not None else DataWarnings(), fill, where, size // 8 + 1 if size else 0
    )


def prime_text_cache(source: Path, events: np.ndarray, width: int, height: int, tolerance_s: float = 1e-6) -> None:
    """Store events already in memory as the cache of text file `source` (they must equal its parse)."""
    write_cache(cache_path(cache_key("text", *file_identity(source), width, height, tolerance_s, 0.0)), events)
