"""`eas-vo cache`: what eas-vo keeps in its cache folder, and clearing it."""

from __future__ import annotations


def add_parser(sub) -> None:
    """`eas-vo cache`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "cache",
        help="show, or clear, what eas-vo keeps in its cache folder",
        description="List each folder of the cache (event caches, simulated sequences, downloads, ...) with "
        "its entries and size; --clear NAME empties one (repeatable). Everything there is rebuilt, simulated "
        "or downloaded again when next needed; clear it while no eas-vo run is using it.",
        epilog="environment: EAS_VO_CACHE_DIR (the cache folder; default $XDG_CACHE_HOME/eas-vo or ~/.cache/eas-vo)",
    )
    parser.add_argument(
        "--clear", action="append", default=[], metavar="NAME", help="empty this cache folder (e.g. events)"
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo cache` on the parsed `args`; returns the exit status."""
    from eas_vo.io.cache import cache_dir, cache_usage, clear_cache

    if args.clear:
        for name, freed in clear_cache(args.clear).items():
            print(f"{name}: cleared, {_size(freed)} freed")
        return 0
    usage = cache_usage()
    print(f"{cache_dir()}:")
    for name, part in usage.items():
        where = f" (a link to {(cache_dir() / name).resolve()})" if part.link else ""
        print(f"  {name:10s} {part.entries:5d} entries {_size(part.size):>9s}  {part.about}{where}")
    total = sum(part.size for part in usage.values())
    print(f"  total {_size(total)}" + ("; eas-vo cache --clear NAME empties one" if usage else " (empty)"))
    return 0


def _size(n_bytes: int) -> str:
    """Bytes as text in B, kB, MB or GB."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes} B"
