"""What made a run (identity.json): the code's hash, the dataset's content and the configuration."""

from __future__ import annotations

import functools
from pathlib import Path

from eas_vo import registry
from eas_vo.config import ResolvedConfig


def run_identity(config: ResolvedConfig) -> dict:
    """What made a run (identity.json): the eas-vo version and a hash of the code that ran
    (code_identity), the dataset's resolved location (an absolute path where it is one), its
    content identity (dataset_identity) and the whole resolved configuration. `compare`
    resumes a cell only when its folder's identity equals the one it would write now."""
    from eas_vo import __version__

    plugin, location = registry.resolve_dataset(config.run.dataset)
    path = Path(location).expanduser()
    plugins = [plugin] + [
        registry.get(kind, name)
        for kind, name in (
            ("frontends", config.run.frontend),
            ("trackers", config.run.tracker),
            ("backends", config.run.backend),
        )
    ]
    return {
        "eas_vo": __version__,
        "code": code_identity(tuple(sorted({cls.__module__.split(".")[0] for cls in plugins} | {"eas_vo"}))),
        "dataset": str(path.resolve()) if path.exists() else location,
        "dataset_content": dataset_identity(plugin, location),
        "config": config.to_toml(),
    }


@functools.cache
def code_identity(packages: tuple[str, ...]) -> str:
    """SHA-1 of the source (.py and .toml files) of `packages` and every subpackage they hold
    (eas-vo's own: its core and the four plugin packages; a third-party plugin's top-level
    package): a run made by other code, a tracker edited in place or another release, is
    another run whatever the version number says."""
    import hashlib
    import importlib

    files = {}  # each file by its dotted name in its package (the same whatever the install's layout)
    for name in packages:
        module = importlib.import_module(name)
        for sub in [module] + [
            importlib.import_module(f"{name}.{part}")
            for part in ("frontends", "trackers", "backends", "datasets", "configs")
            if name == "eas_vo"
        ]:
            for folder in getattr(sub, "__path__", []):
                for path in Path(folder).rglob("*"):
                    if path.suffix in (".py", ".toml") and path.is_file():
                        files[".".join((sub.__name__, *path.relative_to(folder).parts))] = path
            if not hasattr(sub, "__path__") and getattr(sub, "__file__", None):
                files[sub.__name__ + ".py"] = Path(sub.__file__)
    digest = hashlib.sha1()
    for key in sorted(files):
        digest.update(key.encode() + b"\0" + files[key].read_bytes() + b"\0")
    return digest.hexdigest()


def dataset_identity(plugin: type, location: str):
    """The content identity of a dataset: for a file, its eventfile.file_identity; for a folder,
    that of each file in it and the times of its subfolders (a frame added, removed or renamed);
    for a name a plugin fetches, the checksum it is verified against; else None (a simulated
    sequence is a function of the configuration)."""
    from eas_vo.eventfile import file_identity

    path = Path(location).expanduser()
    if path.is_file():
        return list(file_identity(path))
    if path.is_dir():
        entries = sorted(p for p in path.iterdir() if not p.name.startswith("."))
        return {
            p.name: list(file_identity(p)) if p.is_file() else [p.stat().st_mtime_ns, p.stat().st_ctime_ns]
            for p in entries
        }
    return plugin.catalogue().get(location)
