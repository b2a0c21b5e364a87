"""Where a recording's files live: an extracted folder or a `.zip` archive read in place."""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path
from typing import BinaryIO

from eas_vo.errors import DataError
from eas_vo.eventfile import file_identity

#: A file whose presence marks the root of an ECD sequence inside an archive.
MARKERS = ("images.txt", "events.txt")


class FolderSource:
    """Files of an extracted folder."""

    def __init__(self, root: Path):
        self.root = root
        self.location = str(root)
        if not root.is_dir():
            raise DataError(root, "dataset folder not found")

    def label(self, name: str) -> str:
        return str(self.root / name)

    def exists(self, name: str) -> bool:
        return (self.root / name).is_file()

    def open(self, name: str) -> BinaryIO:
        return open(self.root / name, "rb")

    def read_bytes(self, name: str) -> bytes:
        try:
            return (self.root / name).read_bytes()
        except OSError as exc:
            raise DataError(self.label(name), f"cannot read: {exc.strerror or exc}") from None

    def identity(self, name: str) -> tuple:
        return file_identity(self.root / name)

    def size(self, name: str) -> int:
        return (self.root / name).stat().st_size


class ZipSource:
    """Members of a `.zip` archive, read in place (the sequence may sit in one top-level folder)."""

    def __init__(self, path: Path):
        self.path = path
        self.location = str(path)
        if not path.is_file():
            raise DataError(path, "archive not found")
        try:
            self.zip = zipfile.ZipFile(path)
        except (zipfile.BadZipFile, OSError) as exc:
            raise DataError(path, f"not a readable zip archive ({exc})") from None
        names = set(self.zip.namelist())
        prefixes = sorted({n[: -len(m)] for n in names for m in MARKERS if n.endswith(m) and n.count("/") <= 1})
        if len(prefixes) > 1:
            raise DataError(
                path,
                f"holds {len(prefixes)} sequences ({', '.join(p.rstrip('/') or '.' for p in prefixes)}); "
                "a dataset archive must hold one",
            )
        deeper = sorted({n[: -len(m)] for n in names for m in MARKERS if n.endswith("/" + m)})
        if not prefixes and deeper:
            raise DataError(
                path,
                f"holds its sequence in {deeper[0]}, more than one folder deep; "
                "a dataset archive holds it at its top or in one folder",
            )
        self.prefix = prefixes[0] if prefixes else ""

    def label(self, name: str) -> str:
        return f"{self.path}:{self.prefix}{name}"

    def exists(self, name: str) -> bool:
        try:
            self.zip.getinfo(self.prefix + name)
            return True
        except KeyError:
            return False

    def open(self, name: str) -> BinaryIO:
        return _ZipMember(self, name)

    def read_bytes(self, name: str) -> bytes:
        try:
            return self.zip.read(self.prefix + name)
        except KeyError:
            raise DataError(self.label(name), "entry not found in the archive") from None
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
            raise DataError(self.label(name), f"damaged archive entry ({exc})") from None

    def identity(self, name: str) -> tuple:
        info = self.zip.getinfo(self.prefix + name)
        return (*file_identity(self.path), info.filename, info.CRC, info.file_size)

    def size(self, name: str) -> int:
        return self.zip.getinfo(self.prefix + name).file_size


class _ZipMember:
    """A readable archive member whose damage surfaces as a DataError naming the entry."""

    def __init__(self, source: ZipSource, name: str):
        self.source, self.name = source, name
        self.fh = source.zip.open(source.prefix + name)

    def read(self, n: int = -1) -> bytes:
        try:
            return self.fh.read(n)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
            raise DataError(self.source.label(self.name), f"damaged archive entry ({exc})") from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.fh.close()
        return False


def open_source(spec: str | Path) -> FolderSource | ZipSource:
    """The recording at `spec`: the dataset's `.zip`, read in place, or a folder."""
    path = Path(spec)
    return ZipSource(path) if path.suffix.lower() == ".zip" else FolderSource(path)
