"""Event text streamed into cache records (13 bytes/event) one block at a time: the block
parser, the validator and the slow path tied together, memory bounded by the block size (bytes)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import BinaryIO

from eas_vo.errors import DataWarnings
from eas_vo.eventfile.blocks import BLOCK_BYTES, BlockParser, iter_blocks
from eas_vo.eventfile.slowpath import sequential_piece
from eas_vo.eventfile.validate import Validator


def convert_text_to_cache(
    fh: BinaryIO,
    where: str,
    out: BinaryIO,
    width: int,
    height: int,
    tolerance_s: float = 1e-6,
    lenient: bool = False,
    warnings: DataWarnings | None = None,
    block_bytes: int = BLOCK_BYTES,
    origin_s: float = 0.0,
) -> int:
    """Stream event text from `fh` into cache records written to `out`; returns the event count.
    Times are checked as the text states them, then written after the clock origin `origin_s`
    (whole seconds: the subtraction is exact)."""
    warnings = warnings if warnings is not None else DataWarnings()
    validate = Validator(where, width, height, tolerance_s, lenient, warnings)
    total, first_line = 0, 1
    parser = BlockParser(width, height, tolerance_s)
    writer = ThreadPoolExecutor(1)  # writes overlap the parsing of the next block
    pending_write = None
    try:
        for block in iter_blocks(fh, block_bytes):
            records = []
            for piece, packed in parser(block):
                if packed is not None and packed[2] >= validate.last_t:  # packed in parallel, still valid
                    events, newlines, _, validate.last_t = packed
                else:
                    events, newlines = sequential_piece(piece, first_line, validate, where, lenient, warnings)
                if origin_s:
                    events["t"] -= origin_s
                records.append(events.data)
                total += len(events)
                first_line += newlines
            if pending_write is not None:
                pending_write.result()
            pending_write = writer.submit(out.writelines, records)
        if pending_write is not None:
            pending_write.result()
    finally:
        parser.close()
        writer.shutdown()
    return total
