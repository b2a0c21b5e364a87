"""The Event Camera Dataset's published sequences: names, MD5s, and fetching them with pooch.

Each sequence is one `NAME.zip` under the dataset's `datasets/davis/` folder. Fetching
verifies the MD5 and moves the file into place only then (pooch), so a file under its
final name is always whole; one already there and verified is not fetched again.

Environment:
    EAS_VO_DATA_DIR       where sequences are kept (default: $EAS_VO_CACHE_DIR/data, i.e. the cache)
    EAS_VO_DATA_URL       base URL of the zips (a mirror, a local server), or a local folder
                          of them (a path or a file:// URL: an offline mirror)
    EAS_VO_DATA_REGISTRY  a file of `name md5` lines that replaces the built-in registry
"""

from __future__ import annotations

import logging
import os
import re
from importlib import resources
from pathlib import Path
from urllib.parse import unquote, urlsplit

from eas_vo.errors import DataError, EasVoError
from eas_vo.io.atomic import atomic_path, current_umask
from eas_vo.io.cache import cache_folder
from eas_vo.io.download import download_error
from eas_vo.io.tables import text_bytes

logger = logging.getLogger(__name__)

BASE_URL = "https://rpg.ifi.uzh.ch/datasets/davis/"
_MD5 = re.compile(r"[0-9a-fA-F]{32}")


def data_dir() -> Path:
    """Where fetched sequences live: $EAS_VO_DATA_DIR, else the cache folder's `data/`."""
    env = os.environ.get("EAS_VO_DATA_DIR")
    return Path(env) if env else cache_folder("data", "recordings from eas-vo fetch; downloaded again when next needed")


def registry() -> dict[str, str]:
    """{sequence name: MD5 of its zip}: $EAS_VO_DATA_REGISTRY if set, else the built-in one."""
    path = os.environ.get("EAS_VO_DATA_REGISTRY")
    if path:
        try:
            text = text_bytes(Path(path).read_bytes()).decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise DataError(path, f"cannot read the registry named by EAS_VO_DATA_REGISTRY: {exc}") from None
        return parse_registry(text, path)
    return parse_registry(
        resources.files("eas_vo.datasets").joinpath("ecd_registry.txt").read_text(), "ecd_registry.txt"
    )


def parse_registry(text: str, where: str) -> dict[str, str]:
    """`name md5` lines (blank lines and `#` comments skipped) -> {name: md5}."""
    entries: dict[str, str] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        if len(parts) != 2 or not _MD5.fullmatch(parts[1]) or not re.fullmatch(r"[\w.-]+", parts[0]):
            raise DataError(f"{where}:{lineno}", f"expected 'name md5' (32 hex digits), got {line.strip()!r}")
        entries[parts[0]] = parts[1].lower()
    if not entries:
        raise DataError(where, "the registry lists no sequence")
    return entries


def local_path(name: str, folder: str | Path | None = None) -> Path:
    """Where sequence `name` is (or will be) kept."""
    return Path(folder or data_dir()) / f"{name}.zip"


def fetch(name: str, folder: str | Path | None = None, progress: bool = False) -> Path:
    """The verified zip of sequence `name`, downloaded first unless already there and whole.

    A one-line notice (with the size) is logged before a download. Raises EasVoError
    for an unknown name, a server that cannot be reached or does not have the file (before
    any notice), a failed download or a checksum mismatch (nothing is left under the final
    name in either case).
    """
    import pooch

    md5s = registry()
    if name not in md5s:
        raise EasVoError(f"{name}: not an Event Camera Dataset sequence (known: {', '.join(sorted(md5s))})")
    target = local_path(name, folder)
    if target.parent.exists() and not target.parent.is_dir():
        raise EasVoError(f"{target.parent}: the data folder (--dir or EAS_VO_DATA_DIR) is a file")
    found = pooch.file_hash(str(target), alg="md5") if target.is_file() else None
    if found == md5s[name]:
        return target
    url = os.environ.get("EAS_VO_DATA_URL", BASE_URL).rstrip("/") + "/"
    try:
        return _fetch_into(target, url, md5s[name], progress)
    except EasVoError as exc:
        if found is None:
            raise
        raise EasVoError(
            f"{target}: does not match its MD5 {md5s[name]} (found {found}: a partial or another file) "
            f"and was not fetched again: {exc}"
        ) from None


def _fetch_into(target: Path, url: str, md5: str, progress: bool) -> Path:
    """`target` fetched from `url` (a server or a local mirror folder) and checked against `md5`."""
    import pooch
    import requests

    mirror = _local_mirror(url)
    if mirror is not None:
        return _copy_verified(mirror / target.name, target, md5)
    if urlsplit(url).scheme not in ("http", "https", "ftp"):
        raise EasVoError(
            f"EAS_VO_DATA_URL={url!r}: expected an http://, https:// or ftp:// address, "
            "or a local folder (a path or a file:// URL)"
        )
    logger.info(f"fetching {target.name} ({_size_text(url + target.name)}) from {url} into {target.parent}")
    pooch.get_logger().setLevel(logging.WARNING)  # our notice above replaces its own
    store = pooch.create(path=target.parent, base_url=url, registry={target.name: f"md5:{md5}"}, retry_if_failed=2)
    try:
        store.fetch(target.name, progressbar=progress)
    except (ValueError, requests.RequestException, OSError) as exc:  # hash, connection, HTTP status, disk
        raise download_error(exc, url + target.name, f"MD5 {md5} (tried 3 times)", offline_route(target)) from None
    os.chmod(target, 0o666 & ~current_umask())  # pooch's temporary file was private
    return target


def offline_route(target: Path) -> str:
    """What to do without the server, for the zip `target`."""
    return (
        f"copy {target.name} into {target.parent} (or set EAS_VO_DATA_DIR to the folder holding it), "
        "or set EAS_VO_DATA_URL to a folder of the zips"
    )


def _local_mirror(url: str) -> Path | None:
    """The folder `url` names when it is a local one (a file:// URL, or a path without a
    scheme that exists as a folder), else None."""
    parts = urlsplit(url)
    if parts.scheme == "file":
        folder = Path(unquote(parts.path))
    elif parts.scheme == "" or (len(parts.scheme) == 1 and os.name == "nt"):  # a path (C:\ on Windows)
        folder = Path(url)
    else:
        return None
    if not folder.is_dir():
        raise EasVoError(f"EAS_VO_DATA_URL={url!r}: no such folder (a local mirror of the zips)")
    return folder


def _copy_verified(source: Path, target: Path, md5: str) -> Path:
    """Copy `source` to `target` through a temporary file moved into place only once its MD5 is `md5`."""
    import shutil

    import pooch

    if not source.is_file():
        raise EasVoError(f"{source}: not in the local mirror (EAS_VO_DATA_URL), nothing was copied")
    logger.info(
        f"copying {source.name} ({source.stat().st_size / 1e6:.1f} MB) from {source.parent} into {target.parent}"
    )
    with atomic_path(target) as tmp:
        shutil.copyfile(source, tmp)
        found = pooch.file_hash(str(tmp), alg="md5")
        if found != md5:
            raise EasVoError(f"{source}: does not match its MD5 {md5} (found {found}); nothing was kept")
    return target


def _size_text(url: str) -> str:
    """The size the server announces for `url` (HEAD), as text; 'size unknown' if it does not
    say. EasVoError when the server cannot be reached or answers that it has no such file."""
    import requests

    try:
        answer = requests.head(url, allow_redirects=True, timeout=10)
    except requests.ConnectionError as exc:  # refused, unknown host, or no answer to connect (not a slow one)
        raise download_error(exc, url, "MD5", offline_route(data_dir() / Path(urlsplit(url).path).name)) from None
    except requests.RequestException:
        return "size unknown"
    if answer.status_code in (404, 410):
        raise EasVoError(f"{url}: the server has no such file (HTTP {answer.status_code}), nothing was downloaded")
    try:
        size = int(answer.headers["Content-Length"]) if answer.ok else None
    except (KeyError, ValueError):
        size = None
    if size is None:
        return "size unknown" if answer.ok else f"size unknown: HTTP {answer.status_code}"
    return f"{size / 1e9:.2f} GB" if size >= 1e9 else f"{size / 1e6:.1f} MB"
