"""Checks of configuration values, shared by every config dataclass (core and plugins).

One message format: `KEY = VALUE ...; allowed: ...`. The caller (config resolution)
prefixes the section, so a user reads e.g. `tracker.geometry = 'x'; allowed: ...`.
"""

from __future__ import annotations

import math
from typing import Iterable

from eas_vo.errors import ConfigError


def check_range(cfg, key: str, lo: float, hi: float, *, lo_open: bool = False) -> None:
    """Raise ConfigError unless `lo <= cfg.key <= hi` (`lo < cfg.key` when `lo_open`); NaN fails."""
    value = getattr(cfg, key)
    ok = (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise ConfigError(f"{key} = {value} is out of range {bracket}{lo}, {hi}]")


def check_choice(cfg, key: str, allowed: Iterable[str]) -> None:
    """Raise ConfigError unless `cfg.key` is one of `allowed`."""
    allowed = tuple(allowed)
    value = getattr(cfg, key)
    if value not in allowed:
        raise ConfigError(f"{key} = {value!r}; allowed: {', '.join(allowed)}")


def check_vector(cfg, key: str, length: int, unit: str = "") -> None:
    """Raise ConfigError unless `cfg.key` holds `length` finite numbers."""
    value = getattr(cfg, key)
    ok = (
        isinstance(value, (tuple, list))
        and len(value) == length
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    )
    if not ok:
        raise ConfigError(
            f"{key} = {value!r}; expected an array of {length} finite numbers{f' [{unit}]' if unit else ''}"
        )
