"""Event text files (`t x y p` per line) at speed, and their binary cache.

The first read streams the text in blocks through a compiled parser (two threads),
validates each block and appends it to a binary cache file; later reads map the
cache from disk. Memory stays bounded by the block size, so a text file larger
than memory can be converted, and the cached stream is then used window by window.

Cache file: 16-byte header (magic, event count) + packed EVENT_DTYPE records (13 B/event).

Modules (each imports only those above it):
- `kernels`: the numba-compiled parse, validate and pack loops.
- `blocks`: text in blocks of whole lines; the parallel block parser.
- `validate`: row checks carrying the last timestamp from block to block.
- `slowpath`: the line-by-line path for pieces the compiled parser rejected.
- `table`: events held as rows of numbers (HDF5 arrays), checked and packed block by block
  (a whole table at hand, a map of a file's bytes, on several threads at once).
- `convert`: the streaming text -> cache converter tying the above together.
- `cache`: the cache file format: naming, writing, mapping, loading event text through it.
- `text`: writing event text (and priming its cache).
- `libcaer`: the decoders of iniVation's `libcaer` and `libcaer_cmp` packets (a `packets.PacketDecoder` each).
"""

from eas_vo.eventfile.blocks import BLOCK_BYTES, BlockParser, iter_blocks, parse_block
from eas_vo.eventfile.cache import (
    CACHE_MAGIC,
    HEADER_BYTES,
    build_cache,
    cache_key,
    cache_path,
    file_identity,
    load_cached,
    load_event_text,
    open_cache,
    prime_text_cache,
    write_behind,
    write_cache,
)
from eas_vo.eventfile.convert import convert_text_to_cache
from eas_vo.eventfile.table import pack_rows, pack_table
from eas_vo.eventfile.text import format_events, write_events_text
from eas_vo.eventfile.validate import Validator

__all__ = [
    "BlockParser",
    "Validator",
    "build_cache",
    "cache_key",
    "cache_path",
    "convert_text_to_cache",
    "file_identity",
    "format_events",
    "iter_blocks",
    "load_cached",
    "load_event_text",
    "open_cache",
    "pack_rows",
    "pack_table",
    "parse_block",
    "prime_text_cache",
    "write_behind",
    "write_cache",
    "write_events_text",
    "CACHE_MAGIC",
    "HEADER_BYTES",
    "BLOCK_BYTES",
]
