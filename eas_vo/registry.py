"""Plugin discovery through entry points, in the style of xarray's backend loader.

Groups: `eas_vo.frontends`, `eas_vo.backends`, `eas_vo.datasets`. Built-ins
register exactly like third-party plugins. Discovery is cached; a plugin that
fails to import, or a duplicate name, gives a warning instead of a crash.
"""

from __future__ import annotations

import functools
import warnings
from importlib.metadata import entry_points

from eas_vo.errors import EasVoError

KINDS = ("frontends", "backends", "datasets")


@functools.cache
def _entry_points(kind: str) -> dict:
    found: dict = {}
    for ep in entry_points(group=f"eas_vo.{kind}"):
        if ep.name in found:
            warnings.warn(
                f"eas-vo: duplicate {kind[:-1]} plugin {ep.name!r} ({ep.value}); "
                f"keeping {found[ep.name].value}",
                RuntimeWarning,
                stacklevel=2,
            )
            continue
        found[ep.name] = ep
    return found


@functools.cache
def available(kind: str) -> dict[str, type]:
    """Every importable plugin of `kind` ('frontends', 'backends' or 'datasets'), by name."""
    if kind not in KINDS:
        raise ValueError(f"unknown plugin kind {kind!r}")
    loaded = {}
    for name, ep in sorted(_entry_points(kind).items()):
        try:
            loaded[name] = ep.load()
        except Exception as exc:  # a broken third-party plugin must not break the tool
            warnings.warn(
                f"eas-vo: {kind[:-1]} plugin {name!r} ({ep.value}) failed to load: {exc}",
                RuntimeWarning,
                stacklevel=2,
            )
    return loaded


def get(kind: str, name: str) -> type:
    """The plugin class called `name`; an unknown name lists what is installed."""
    plugins = available(kind)
    if name not in plugins:
        installed = ", ".join(plugins) or "none"
        raise EasVoError(f"unknown {kind[:-1]} {name!r}; installed: {installed}")
    return plugins[name]
