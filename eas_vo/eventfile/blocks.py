"""Event text in blocks of whole lines (BLOCK_BYTES = 64 MiB at most, plus the rest of a
line), and the parser that parses, validates and packs a block's pieces on threads at once."""

from __future__ import annotations

import io
import mmap
import os
from concurrent.futures import ThreadPoolExecutor
from typing import BinaryIO, Iterator

import numpy as np

from eas_vo.eventfile.kernels import parse_and_pack
from eas_vo.types import EVENT_DTYPE

BLOCK_BYTES = 64 << 20


def iter_blocks(fh: BinaryIO, block_bytes: int = BLOCK_BYTES) -> Iterator[np.ndarray]:
    """Blocks of whole lines (the last may lack its newline) as uint8 arrays.

    A regular file is memory-mapped (no copy; each block's pages are released once it is
    parsed, so a file larger than memory streams through). Other streams (zip members) are
    read chunk by chunk in the background, the line split by a chunk boundary coming as a
    small block of its own.
    """
    try:
        fileno = fh.fileno()
        size = os.fstat(fileno).st_size
    except (AttributeError, OSError, io.UnsupportedOperation):
        fileno = None
    if fileno is not None and size > 0:
        # Not closed explicitly: blocks handed out may outlive the loop; the mapping goes with them.
        mapped = mmap.mmap(fileno, 0, access=mmap.ACCESS_READ)
        mapped.madvise(mmap.MADV_SEQUENTIAL)
        text = np.frombuffer(mapped, np.uint8)
        page = mmap.PAGESIZE
        start = 0
        while start < size:
            end = min(start + block_bytes, size)
            if end < size:
                newline = mapped.rfind(b"\n", start, end)
                end = newline + 1 if newline >= start else (mapped.find(b"\n", end) + 1 or size)
            yield text[start:end]
            first_page = start - start % page
            mapped.madvise(mmap.MADV_DONTNEED, first_page, (end - first_page) // page * page)
            start = end
        return
    with ThreadPoolExecutor(1) as reader:
        future = reader.submit(fh.read, block_bytes)
        carry = b""
        while True:
            chunk = future.result()
            if not chunk:
                if carry:
                    yield np.frombuffer(carry, np.uint8)
                return
            future = reader.submit(fh.read, block_bytes)
            first = chunk.find(b"\n") + 1
            if first == 0:
                carry += chunk
                continue
            yield np.frombuffer(carry + chunk[:first], np.uint8)
            last = chunk.rfind(b"\n") + 1
            if last > first:
                yield np.frombuffer(chunk, np.uint8, last - first, first)
            carry = chunk[last:]


def _split_at_newline(buf: np.ndarray, parts: int) -> list[np.ndarray]:
    bounds = [0]
    for k in range(1, parts):
        guess = max(bounds[-1], len(buf) * k // parts)
        nl = np.flatnonzero(buf[guess : guess + (1 << 20)] == 10)
        bounds.append(guess + int(nl[0]) + 1 if len(nl) else bounds[-1])
    bounds.append(len(buf))
    return [buf[a:b] for a, b in zip(bounds, bounds[1:])]


def _terminated(piece: np.ndarray) -> np.ndarray:
    """The piece, ending with a newline (the compiled scans stop on it)."""
    if len(piece) and piece[-1] != 10:
        return np.concatenate([piece, np.array([10], np.uint8)])
    return piece


class BlockParser:
    """Parses, validates and packs blocks of lines in `threads` pieces at once, each piece as
    if it started the stream; the caller accepts a piece when its first time is not before
    the previous piece's last, and takes the sequential path otherwise.

    Packed records live in one of two alternating buffer sets that are reused, sparing fresh
    ones' page faults (docs/speed.md, "The event parser and its cache"): valid until the
    block after next.
    """

    def __init__(self, width: int, height: int, tolerance_s: float, threads: int = 2):
        self.limits = (width, height, tolerance_s)
        self.threads = threads
        self.pool = ThreadPoolExecutor(threads) if threads > 1 else None
        self.buffers: dict = {}
        self.calls = 0

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()

    def _buffer(self, key, rows: int) -> np.ndarray:
        if key not in self.buffers or len(self.buffers[key]) < rows:
            self.buffers[key] = np.empty(max(rows, 1024), EVENT_DTYPE)
        return self.buffers[key]

    def __call__(self, buf: np.ndarray) -> list[tuple]:
        """Per piece of `buf`, in order: (the piece, and if every line was plain and valid:
        (records, newlines, first time, last time), else None)."""
        pieces = [_terminated(p) for p in _split_at_newline(buf, self.threads if len(buf) > (1 << 20) else 1)]
        parity = self.calls % 2
        self.calls += 1

        def run(k):
            piece = pieces[k]
            out = self._buffer((parity, k), len(piece) // 8 + 1)  # a line has at least 8 bytes
            n, bad, lines, first_t, last_t = parse_and_pack(piece, *self.limits, -np.inf, out.view(np.uint8))
            return piece, (None if bad >= 0 else (out[:n], lines, first_t, last_t))

        return list(self.pool.map(run, range(len(pieces)))) if len(pieces) > 1 else [run(0)]


def parse_block(
    buf: np.ndarray, width: int = 65535, height: int = 65535, tolerance_s: float = np.inf
) -> np.ndarray | None:
    """Plain, valid `t x y p` lines -> EVENT_DTYPE records (a copy), or None if any line is not."""
    parser = BlockParser(width, height, tolerance_s, threads=1)
    try:
        ((_, result),) = parser(buf)
    finally:
        parser.close()
    return None if result is None else result[0].copy()
