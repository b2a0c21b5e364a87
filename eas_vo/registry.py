"""Plugin discovery through entry points, in the style of xarray's backend loader.

Groups: `eas_vo.datasets`, `eas_vo.frontends`, `eas_vo.trackers`, `eas_vo.backends`.
Built-ins register exactly like third-party plugins. Discovery is cached; a
third-party plugin that fails to import, or a duplicate name, gives a warning
instead of a crash; a built-in that fails to import is a broken installation and
every lookup says so. `resolve_dataset` is the one place that decides what a
`--dataset` string means.
"""

from __future__ import annotations

import functools
import warnings
from importlib.metadata import entry_points
from pathlib import Path

from eas_vo.errors import EasVoError

KINDS = ("datasets", "frontends", "trackers", "backends")
_BUILTIN_PREFIX = "eas_vo."


@functools.cache
def _entry_points(kind: str) -> dict:
    found: dict = {}
    for ep in entry_points(group=f"eas_vo.{kind}"):
        if ep.name in found:
            warnings.warn(
                f"eas-vo: duplicate {kind[:-1]} plugin {ep.name!r} ({ep.value}); keeping {found[ep.name].value}",
                RuntimeWarning,
                stacklevel=2,
            )
            continue
        found[ep.name] = ep
    return found


@functools.cache
def _load(kind: str) -> tuple[dict[str, type], dict[str, str]]:
    """({name: plugin class}, {name: why it failed to load}) for `kind`."""
    if kind not in KINDS:
        raise ValueError(f"unknown plugin kind {kind!r}")
    loaded, failed = {}, {}
    for name, ep in sorted(_entry_points(kind).items()):
        try:
            loaded[name] = ep.load()
        except Exception as exc:  # a broken third-party plugin must not break the tool
            failed[name] = f"{ep.value}: {type(exc).__name__}: {exc}"
            if not ep.value.startswith(_BUILTIN_PREFIX):
                warnings.warn(
                    f"eas-vo: {kind[:-1]} plugin {name!r} failed to load ({failed[name]})", RuntimeWarning, stacklevel=2
                )
    return loaded, failed


def names(kind: str) -> list[str]:
    """The names of the installed plugins of `kind` (one of KINDS), sorted, from their entry
    points alone: nothing is imported (for help texts; `available` says which import)."""
    if kind not in KINDS:
        raise ValueError(f"unknown plugin kind {kind!r}")
    return sorted(_entry_points(kind))


def available(kind: str) -> dict[str, type]:
    """Every importable plugin of `kind` (one of KINDS), by name."""
    return _load(kind)[0]


def broken_builtins(kind: str) -> dict[str, str]:
    """Built-in plugins of `kind` that failed to import, with the reason: a broken installation."""
    return {name: why for name, why in _load(kind)[1].items() if why.startswith(_BUILTIN_PREFIX)}


def _installation_problem(kind: str, name: str | None = None) -> str:
    """A clause naming the built-in plugins of `kind` that failed to import (`name`'s alone if it
    is one of them), with the likely cause; empty when there are none."""
    broken = broken_builtins(kind)
    if name in broken:
        broken = {name: broken[name]}
    if not broken:
        return ""
    import eas_vo

    failures = "; ".join(f"{n} ({why})" for n, why in broken.items())
    text = f"; built-in {kind} that failed to import: {failures}"
    if any("No module named 'eas_vo." in why for why in broken.values()):
        text += (
            f"; eas_vo was imported from {Path(eas_vo.__file__).parent}: if that is a source checkout "
            "shadowing the installed package, run from another folder or install with `pip install -e .`"
        )
    return text


def get(kind: str, name: str) -> type:
    """The plugin class called `name`; an unknown name lists what is installed."""
    plugins = available(kind)
    if name not in plugins:
        installed = ", ".join(plugins) or "none"
        raise EasVoError(f"unknown {kind[:-1]} {name!r}; installed: {installed}{_installation_problem(kind, name)}")
    return plugins[name]


def resolve_dataset(spec: str) -> tuple[type, str]:
    """(dataset plugin class, location) for a `--dataset` value.

    `NAME:LOCATION` with NAME an installed dataset plugin is explicit. Otherwise every
    dataset plugin is asked, in name order, whether it `can_open` the spec; exactly one
    must say yes.
    """
    plugins = available("datasets")
    scheme, sep, location = spec.partition(":")
    explicit = sep and len(scheme) > 1 and scheme.isidentifier()  # (a one-letter scheme is a drive letter)
    if explicit and scheme in plugins:
        if not location:
            raise EasVoError(f"--dataset {spec}: names no location after '{scheme}:'")
        return plugins[scheme], location
    if explicit and not Path(spec).exists():
        raise EasVoError(
            f"--dataset {spec}: no dataset plugin {scheme!r} (installed: {', '.join(plugins) or 'none'})"
            f"{_installation_problem('datasets', scheme)}"
        )
    claims = [cls for _, cls in sorted(plugins.items()) if _claims(cls, spec)]
    if len(claims) == 1:
        return claims[0], spec
    if len(claims) > 1:
        names = ", ".join(cls.name for cls in claims)
        raise EasVoError(f"{spec}: several dataset plugins can open it ({names}); write NAME:{spec} to choose")
    if not Path(spec).exists():
        raise EasVoError(
            f"{spec}: dataset not found (no such file or folder, and no dataset plugin "
            f"recognises it; installed: {', '.join(plugins) or 'none'}){_installation_problem('datasets')}"
        )
    raise EasVoError(
        f"{spec}: no installed dataset plugin can open it (installed: {', '.join(plugins) or 'none'}; "
        f"write NAME:{spec} to force one){_installation_problem('datasets')}"
    )


def fetchable(spec: str) -> tuple[type, str]:
    """(dataset plugin class, recording name) for an `eas-vo fetch` name: `PLUGIN:NAME`, or a
    NAME exactly one plugin's catalogue lists."""
    plugins = available("datasets")
    scheme, sep, name = spec.partition(":")
    if sep:
        if scheme not in plugins:
            raise EasVoError(f"{spec}: no dataset plugin {scheme!r} (installed: {', '.join(plugins) or 'none'})")
        candidates = [plugins[scheme]]
    else:
        candidates, name = list(plugins.values()), spec
    owners = [cls for cls in candidates if name in cls.catalogue()]
    if len(owners) == 1:
        return owners[0], name
    if owners:
        raise EasVoError(
            f"{spec}: several dataset plugins list it ({', '.join(c.name for c in owners)}); write PLUGIN:{spec}"
        )
    known = sorted(f"{cls.name}:{n}" if sep else n for cls in candidates for n in cls.catalogue())
    raise EasVoError(f"{spec}: no dataset plugin can fetch it (known: {', '.join(known) or 'none'})")


def _claims(cls: type, location: str) -> bool:
    try:
        return bool(cls.can_open(location))
    except Exception as exc:  # can_open must never raise; a plugin that does is skipped, loudly
        warnings.warn(
            f"eas-vo: dataset plugin {cls.name!r}: can_open raised {type(exc).__name__}: {exc}",
            RuntimeWarning,
            stacklevel=3,
        )
        return False


def open_dataset(spec: str, config=None, *, need_camera: bool = True):
    """Open a `--dataset` value with its plugin (and that plugin's config, default if None).
    A dataset that sets no `label` is labelled with the spec. `need_camera`: refuse a dataset
    without a camera (its `no_camera_reason`, which names the file); False only to describe it."""
    cls, location = resolve_dataset(spec)
    dataset = cls(location, config if config is not None else cls.Config())
    if not dataset.label:
        dataset.label = spec
    if need_camera and dataset.camera is None:
        raise EasVoError(dataset.no_camera_reason)
    return dataset
