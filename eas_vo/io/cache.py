"""The user's cache folder: its parts (event caches, simulated sequences, downloads), what each
holds, and clearing them."""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import write_text_atomic


def cache_dir() -> Path:
    """User cache folder: $EAS_VO_CACHE_DIR, else $XDG_CACHE_HOME/eas-vo, else ~/.cache/eas-vo."""
    env = os.environ.get("EAS_VO_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eas-vo"


#: The file in each cache folder saying what it holds (cache_folder, cache_usage).
CACHE_ABOUT = ".about"


def cache_folder(name: str, about: str) -> Path:
    """The cache folder's part `name` (created when possible), with a line saying what it
    holds and what clearing it costs (`eas-vo cache` shows it; rewritten when it differs)."""
    folder = cache_dir() / name
    line = folder / CACHE_ABOUT
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not line.is_file() or line.read_text(errors="replace") != about + "\n":
            write_text_atomic(line, about + "\n")
    except OSError:
        pass  # a read-only cache: whoever writes there says why
    return folder


@dataclass(frozen=True)
class CachePart:
    """One folder of the cache: its entries and bytes (hidden files, such as writes under way
    and CACHE_ABOUT, left out; links inside never followed), what it holds (its CACHE_ABOUT
    line, "" without one), and whether the part itself is a link to a folder elsewhere."""

    entries: int
    size: int
    about: str
    link: bool = False


def _visible(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if not p.name.startswith(".")]


def cache_usage() -> dict[str, CachePart]:
    """Each folder of the cache folder (a link to a folder counts as one), by name."""
    root = cache_dir()
    if root.exists() and not root.is_dir():
        raise EasVoError(f"{root}: the cache folder (EAS_VO_CACHE_DIR) is not a folder")
    usage = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []:
        entries = _visible(folder)
        files = [
            f
            for e in entries
            for f in ([e] if not e.is_dir() or e.is_symlink() else e.rglob("*"))
            if f.is_file() and not f.is_symlink() and not f.name.startswith(".")
        ]
        about = folder / CACHE_ABOUT
        usage[folder.name] = CachePart(
            len(entries),
            sum(f.lstat().st_size for f in files),
            about.read_text(errors="replace").strip() if about.is_file() else "",
            folder.is_symlink(),
        )
    return usage


def clear_cache(names: list[str]) -> dict[str, int]:
    """Empty the cache folders `names` (all checked first), leaving hidden files (writes under
    way, CACHE_ABOUT) and what links point to; the bytes freed by each. A folder that is a link
    is refused: its target is not the cache's to empty."""
    usage = cache_usage()
    unknown = [name for name in names if name not in usage]
    if unknown:
        raise EasVoError(f"cache {unknown[0]!r}: not in {cache_dir()} (there: {', '.join(usage) or 'nothing'})")
    linked = [name for name in names if usage[name].link]
    if linked:
        link = cache_dir() / linked[0]
        raise EasVoError(
            f"cache {linked[0]!r}: {link} is a link to {link.resolve()}, which eas-vo does not empty; "
            "remove the link, or empty that folder yourself"
        )
    for name in dict.fromkeys(names):
        for entry in _visible(cache_dir() / name):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
    return {name: usage[name].size for name in dict.fromkeys(names)}
