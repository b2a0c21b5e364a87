"""Run configuration: TOML files -> frozen dataclasses, with command-line overrides.

Sections: `[run]` (what to run), `[dataset]`, `[frontend]`, `[tracker]`, `[backend]`.
Each plugin section holds the keys of the chosen plugin; per-plugin tables such as
`[frontend.eas]` apply only when that plugin is chosen, so one file can configure
every frontend. Precedence: dataclass defaults < file < CLI flags < `--set`.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

from eas_vo import registry
from eas_vo.errors import ConfigError
from eas_vo.validation import check_range, check_vector

SECTIONS = ("run", "dataset", "frontend", "tracker", "backend")
#: The frontend a tracker that reads no images runs with (Tracker.reads_images).
NO_IMAGES = "no_image"
#: The largest run.time_offset_s [s]: a latency between two clocks of one rig; a larger gap is
#: another clock origin (dataset.ground_truth_time_offset_s).
TIME_OFFSET_LIMIT_S = 10.0


@dataclass(frozen=True)
class RunConfig:
    """What to run.

    Attributes:
        dataset: `PLUGIN:LOCATION`, or a location one dataset plugin recognises (a folder,
            a `.zip`, a `.bag`); default the embedded `synthetic:default`.
        frontend, tracker, backend: plugin names (frontend: `no_image` whatever is given when the
            tracker reads no images, Tracker.reads_images).
        start_s, duration_s: processed window, from the sequence's first timestamp [s].
        time_offset_s: ground truth is sampled at `t_frame + time_offset_s` [s].
        time_offset_auto: estimate the offset from the data instead (relative rotations
            against ground truth); the estimate is reported in metrics.json.
        orb_stats: also count ORB keypoints per image and matches between adjacent images
            (the paper's Table 2), reported in metrics.json.
        imu_rotvec_cam: the rig's camera-to-IMU rotation R_imu_cam as a rotation vector [rad]
            (v_imu = R_imu_cam v_cam): trackers and backends get the IMU's readings rotated
            into the camera frame by it. The identity: the simulator's (and, within 1 deg, the
            Event Camera Dataset's: docs/imu.md). Every run checks it against the images (a warning).
        imu_time_offset_s: IMU time = frame time + this [s].
        imu_time_offset_auto: the backend reads the gyro on the clock the images ask for when
            they clearly ask for another (the run's IMU check; metrics.json reports the offset
            used); the tracker's prediction keeps imu_time_offset_s.
    """

    dataset: str = "synthetic:default"
    frontend: str = "eas"
    tracker: str = "klt"
    backend: str = "chain"
    start_s: float = 0.0
    duration_s: float = math.inf
    time_offset_s: float = 0.0
    time_offset_auto: bool = False
    orb_stats: bool = False
    imu_rotvec_cam: tuple = (0.0, 0.0, 0.0)
    imu_time_offset_s: float = 0.0
    imu_time_offset_auto: bool = False

    def validate(self) -> None:
        check_vector(self, "imu_rotvec_cam", 3, "rad")
        check_range(self, "imu_time_offset_s", -1.0, 1.0)
        check_range(self, "start_s", 0.0, math.inf)
        check_range(self, "time_offset_s", -TIME_OFFSET_LIMIT_S, TIME_OFFSET_LIMIT_S)
        check_range(self, "duration_s", 0.0, math.inf, lo_open=True)


@dataclass(frozen=True)
class ResolvedConfig:
    """Every section, resolved against the chosen plugins; `origin` says what made it for
    titles ("paper.toml --set tracker.geometry=rotation", "defaults"), not part of its identity."""

    run: RunConfig
    dataset: Any
    frontend: Any
    tracker: Any
    backend: Any
    origin: str = field(default="", compare=False)

    def to_toml(self) -> str:
        """The resolved configuration as TOML; loading it reproduces this object."""
        lines = []
        for section in SECTIONS:
            lines.append(f"[{section}]")
            for f in fields(getattr(self, section)):
                lines.append(f"{f.name} = {_toml_value(getattr(getattr(self, section), f.name))}")
            lines.append("")
        return "\n".join(lines)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return '"' + str(value).replace("\\", "\\\\").replace('"', '\\"') + '"'


#: Keys that left [tracker] and [backend] for [run] (moved there when an older file holds them).
MOVED_TO_RUN = ("imu_rotvec_cam", "imu_time_offset_s")


def build(cls, values: dict, section: str):
    """Instantiate the frozen dataclass `cls` from `values`, rejecting unknown keys and bad types."""
    hints = get_type_hints(cls)
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ConfigError(
            f"unknown key {section}.{unknown[0]}; allowed keys: {', '.join(sorted(known)) or 'none'}"
        )
    kwargs = {k: _coerce(v, hints[k], f"{section}.{k}") for k, v in values.items()}
    try:
        cfg = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"[{section}]: {exc}") from None
    validate = getattr(cfg, "validate", None)
    if validate is not None:
        try:
            validate()
        except ConfigError as exc:
            raise ConfigError(f"{section}.{exc}") from None
    for key, value in kwargs.items():
        if hints[key] is tuple and not isinstance(value, tuple):  # not an array, and validate() did not say so
            raise ConfigError(f"{section}.{key} must be an array, e.g. {_toml_value(getattr(cls, key, ()))}, got {value!r}")
    return cfg


def _coerce(value, hint, key: str):
    if hint is bool:
        if isinstance(value, bool):
            return value
    elif hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif hint is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif hint is str:
        if isinstance(value, str):
            return value
    elif hint is tuple:
        # TOML arrays arrive as lists; a frozen config holds tuples. Anything else is left for
        # the config's validate() to refuse, which says what it expects (e.g. 3 numbers [rad]).
        return tuple(value) if isinstance(value, (list, tuple)) else value
    else:
        return value
    raise ConfigError(f"{key} must be {hint.__name__}, got {value!r}")


def parse_set(assignment: str) -> tuple[list[str], Any]:
    """`section.key=value` -> (['section', 'key'], value); value parsed as TOML, else a string."""
    path, sep, text = assignment.partition("=")
    keys = path.strip().split(".")
    if not sep or len(keys) < 2 or keys[0] not in SECTIONS or not all(keys):
        raise ConfigError(
            f"--set {assignment!r}: expected SECTION.KEY=VALUE with SECTION one of {', '.join(SECTIONS)}"
        )
    try:
        value = tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()
    return keys, value


def bundled_configs() -> dict[str, Path]:
    """Configs shipped with the package (`configs/*.toml`), by stem."""
    root = resources.files("eas_vo.configs")
    return {Path(p.name).stem: Path(str(p)) for p in root.iterdir() if p.name.endswith(".toml")}


def read_config_file(path: str | Path) -> dict:
    """Parse a TOML config; a bare name such as `paper` selects a bundled config."""
    p = Path(path)
    if not p.exists():
        bundled = bundled_configs()
        if str(path) in bundled:
            p = bundled[str(path)]
        else:
            names = ", ".join(sorted(bundled)) or "none"
            raise ConfigError(f"{path}: config file not found (bundled configs: {names})")
    if not p.is_file():
        raise ConfigError(f"{p}: not a config file (a directory?)")
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a byte-order mark, as some editors write, is read past
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        raise ConfigError(f"{p}: unknown section [{unknown[0]}]; allowed: {', '.join(SECTIONS)}")
    _check_tables(raw, str(p))
    return raw


def _check_tables(raw: dict, where: str) -> None:
    """Each section in `raw` a table, and so is each plugin table in one ([tracker.klt]: a key
    named after an installed plugin of the section's kind); else a one-line error from `where`."""
    for section, table in raw.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {section} must be a table ([{section}] and its keys), found {_found(table)}")
        installed = registry.available(f"{section}s") if section != "run" else {}
        for key, value in table.items():
            if key in installed and not isinstance(value, dict):
                raise ConfigError(f"{where}: {section}.{key} must be a table (the {key} {section}'s keys, "
                                  f"[{section}.{key}]), found {_found(value)}")


def _found(value) -> str:
    """A TOML value that is not a table, for a message: arrays of tables in words, others as written."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return "an array of tables"
    return _toml_value(value)


def run_section(config_file: str | Path | None = None, assignments: list[str] = ()) -> RunConfig:
    """The [run] section alone: defaults, the config file's [run], `--set run.KEY=V` (what
    `compare` takes its default tracker and backend from)."""
    raw = dict((read_config_file(config_file) if config_file else {}).get("run", {}))
    for assignment in assignments:
        keys, value = parse_set(assignment)
        if keys[0] == "run" and len(keys) == 2:
            raw[keys[1]] = value
    return build(RunConfig, raw, "run")


def resolve(
    config_file: str | Path | None = None,
    run_overrides: dict | None = None,
    assignments: list[str] = (),
) -> ResolvedConfig:
    """Merge defaults, a config file, CLI flags and `--set` assignments; validate everything."""
    raw: dict = read_config_file(config_file) if config_file else {}
    raw = {s: dict(raw.get(s, {})) for s in SECTIONS}
    raw["run"].update({k: v for k, v in (run_overrides or {}).items() if v is not None})
    for assignment in assignments:
        keys, value = parse_set(assignment)
        _check_tables({keys[0]: {keys[1]: value if len(keys) == 2 else {}}}, f"--set {assignment}")
        table = raw[keys[0]]
        for k in keys[1:-1]:
            table = table.setdefault(k, {})
            if not isinstance(table, dict):
                raise ConfigError(f"--set {assignment!r}: {k} is not a table")
        table[keys[-1]] = value

    _move_to_run(raw)
    run = build(RunConfig, raw["run"], "run")
    if not registry.get("trackers", run.tracker).reads_images:  # nothing would look at the images
        run = dataclasses.replace(run, frontend=NO_IMAGES)
    dataset_cls, _ = registry.resolve_dataset(run.dataset)
    chosen = {
        "dataset": dataset_cls,
        "frontend": registry.get("frontends", run.frontend),
        "tracker": registry.get("trackers", run.tracker),
        "backend": registry.get("backends", run.backend),
    }
    sections = {name: build(cls.Config, _plugin_table(raw[name], name, cls), f"{name}.{cls.name}") for name, cls in chosen.items()}
    origin = " ".join([Path(config_file).name if config_file else "defaults"] + [f"--set {a}" for a in assignments])
    return ResolvedConfig(run=run, **sections, origin=origin)


def _move_to_run(raw: dict) -> None:
    """Move MOVED_TO_RUN keys found in [tracker] or [backend] (or the chosen plugin's table
    there), as every config.toml written before they moved holds them, into [run] unless [run]
    (or --set run.KEY) sets them; old places that disagree (the rig has one IMU) are an error
    naming them. Other plugins' tables lose the keys unread."""
    for key in MOVED_TO_RUN:
        found = {}
        for section in ("tracker", "backend"):
            chosen = raw["run"].get(section, getattr(RunConfig, section))
            for name, table in [(section, raw[section])] + [(f"{section}.{k}", t) for k, t in raw[section].items()
                                                            if isinstance(t, dict)]:
                if key in table and name in (section, f"{section}.{chosen}"):
                    found[f"{name}.{key}"] = table.pop(key)
                table.pop(key, None)
        if len({repr(_as_numbers(v)) for v in found.values()}) > 1:
            places = ", ".join(f"{where} = {_toml_value(v)}" for where, v in found.items())
            raise ConfigError(f"{places}: the rig has one IMU; set run.{key} only")
        if found and key not in raw["run"]:
            raw["run"][key] = next(iter(found.values()))


def _as_numbers(value):
    """A number, or a list of them, as floats (to compare values written 0 or 0.0); else as is."""
    try:
        return tuple(float(x) for x in value) if isinstance(value, (list, tuple)) else float(value)
    except (TypeError, ValueError):
        return value


def _plugin_table(table: dict, section: str, plugin: type) -> dict:
    """Flat keys of a section, over its `[section.<name>]` table; other plugins' tables dropped.

    A table must be named after an installed plugin of the section's kind, so that a typo
    (`[frontend.eass]`) is an error rather than silently ignored; a table under one of the
    plugin's own keys is kept, for `build` to say what that key takes.
    """
    installed = registry.available(f"{section}s")
    own_keys = {f.name for f in fields(plugin.Config)}
    for key, value in table.items():
        if isinstance(value, dict) and key not in installed and key not in own_keys:
            raise ConfigError(
                f"unknown table {section}.{key}: not an installed {section} plugin ({', '.join(installed) or 'none'})"
            )
    merged = dict(table.get(plugin.name, {}))  # a table: _check_tables saw to it
    merged.update({k: v for k, v in table.items() if k in own_keys or not isinstance(v, dict)})
    return merged
