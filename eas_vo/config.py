"""Run configuration: TOML files -> frozen dataclasses, with command-line overrides.

Sections: `[run]` (what to run), `[dataset]`, `[frontend]`, `[tracker]`, `[backend]`.
Each plugin section holds the keys of the chosen plugin; per-plugin tables such as
`[frontend.eas]` apply only when that plugin is chosen, so one file can configure
every frontend. Precedence is by source: dataclass defaults < file < CLI options < `--set`,
whether a key is written flat (`[tracker] threshold2`) or in the plugin's table; within a file
the plugin's table, the more specific, wins over the flat key (whatever their order: a flat
value for every tracker, the table's for klt), and among `--set` assignments the later wins.
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
from eas_vo.io.tables import text_bytes
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
        raise ConfigError(f"unknown key {section}.{unknown[0]}; allowed keys: {', '.join(sorted(known)) or 'none'}")
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
            raise ConfigError(
                f"{section}.{key} must be an array, e.g. {_toml_value(getattr(cls, key, ()))}, got {value!r}"
            )
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
        raise ConfigError(f"--set {assignment!r}: expected SECTION.KEY=VALUE with SECTION one of {', '.join(SECTIONS)}")
    try:
        value = tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()
    return keys, value


def assignment(key: str, value) -> str:
    """The `--set` assignment `KEY=VALUE` giving `key` (`section.key`) the Python `value` (bool,
    int, float, str or a sequence of them), written as TOML so that parse_set reads it back as given."""
    return f"{key}={_toml_value(value)}"


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
        raw = tomllib.loads(
            text_bytes(p.read_bytes()).decode("utf-8")
        )  # a byte-order mark, as some editors write, is read past
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        raise ConfigError(f"{p}: unknown section [{unknown[0]}]; allowed: {', '.join(SECTIONS)}")
    _check_tables(raw, str(p))
    return raw


def _installed(section: str) -> dict:
    """The installed plugins whose tables a section may hold ([run] holds none)."""
    return registry.available(f"{section}s") if section != "run" else {}


def _check_tables(raw: dict, where: str) -> None:
    """Each section in `raw` a table, and so is each plugin table in one ([tracker.klt]: a key
    named after an installed plugin of the section's kind); else a one-line error from `where`."""
    for section, table in raw.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {section} must be a table ([{section}] and its keys), found {_found(table)}")
        installed = _installed(section)
        for key, value in table.items():
            if key in installed and not isinstance(value, dict):
                raise ConfigError(
                    f"{where}: {section}.{key} must be a table (the {key} {section}'s keys, "
                    f"[{section}.{key}]), found {_found(value)}"
                )


def _found(value) -> str:
    """A TOML value that is not a table, for a message: arrays of tables in words, others as written."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return "an array of tables"
    return _toml_value(value)


@dataclass(frozen=True)
class _Source:
    """The values one source of configuration gives, in the order given.

    Attributes:
        where: the source in messages (a config file's path, `--set`, `options`).
        entries: (section, plugin or None, key, value): `[tracker.klt] threshold2` is
            ("tracker", "klt", "threshold2", v); a flat `[tracker] threshold2`, plugin None.
        ordered: a later value for a key wins over an earlier one (`--set`, whose order is the
            user's); otherwise (a file) a key in the chosen plugin's table wins over its flat twin.
    """

    where: str
    entries: tuple
    ordered: bool


def _file_source(config_file: str | Path) -> _Source:
    entries = []
    for section, table in read_config_file(config_file).items():
        installed = _installed(section)
        for key, value in table.items():
            if key in installed:  # a plugin table: read_config_file saw to it
                entries += [(section, key, k, v) for k, v in value.items()]
            else:
                entries.append((section, None, key, value))
    return _Source(str(config_file), tuple(entries), ordered=False)


def _set_source(assignments) -> _Source:
    entries = []
    for assignment in assignments:
        keys, value = parse_set(assignment)
        _check_tables({keys[0]: {keys[1]: value if len(keys) == 2 else {}}}, f"--set {assignment}")
        section, rest = keys[0], keys[1:]
        plugin = rest.pop(0) if len(rest) > 1 and rest[0] in _installed(section) else None
        for key in reversed(rest[1:]):  # section.key.sub=v: a table under key, for build to refuse by the key's type
            value = {key: value}
        entries.append((section, plugin, rest[0], value))
    return _Source("--set", tuple(entries), ordered=True)


def _sources(config_file, run_overrides: dict | None, assignments) -> list[_Source]:
    """The sources in rising precedence: the config file, the command's options (`run_overrides`,
    None meaning not given), `--set`; the dataclass defaults lie under them all."""
    options = tuple(("run", None, k, v) for k, v in (run_overrides or {}).items() if v is not None)
    return [
        *([_file_source(config_file)] if config_file else []),
        _Source("options", options, ordered=True),
        _set_source(assignments),
    ]


def _values(source: _Source, section: str, plugin: type | None = None) -> dict[str, tuple[str, Any]]:
    """What `source` gives the chosen `plugin` of `section` (None for [run]): key -> (the key as
    written, value); flat keys and the plugin's own table alike, other plugins' tables dropped.

    A table must be named after an installed plugin of the section's kind, so that a typo
    (`[frontend.eass]`) is an error rather than silently ignored; a table under one of the
    plugin's own keys is kept, for `build` to say what that key takes.
    """
    own_keys = {f.name for f in fields(plugin.Config)} if plugin is not None else set()
    own_table = plugin.name if plugin is not None else None
    found: dict[str, tuple[str, Any]] = {}
    for entry_section, table, key, value in source.entries:
        if entry_section != section or table not in (None, own_table):
            continue
        if plugin is not None and table is None and isinstance(value, dict) and key not in own_keys:
            installed = ", ".join(_installed(section)) or "none"
            raise ConfigError(
                f"{source.where}: unknown table {section}.{key}: not an installed {section} plugin ({installed})"
            )
        if key not in found or source.ordered or table is not None:
            found[key] = (".".join(filter(None, (section, table, key))), value)
    return found


def _run_config(sources: list[_Source], moved: list[dict] | None = None) -> RunConfig:
    """[run] from the sources (each with the keys `_move_to_run` found in it), the frontend
    `no_image` when the tracker reads no images (nothing would look at them)."""
    values = {}
    for i, source in enumerate(sources):
        given = {**(moved[i] if moved else {}), **_values(source, "run")}  # a source's [run] over its old places
        values.update((key, value) for key, (_, value) in given.items())
    run = build(RunConfig, values, "run")
    if not registry.get("trackers", run.tracker).reads_images:
        run = dataclasses.replace(run, frontend=NO_IMAGES)
    return run


def run_section(config_file: str | Path | None = None, assignments: list[str] = ()) -> RunConfig:
    """The [run] section alone: defaults, the config file's [run], `--set run.KEY=V` (what
    `compare` takes its default tracker and backend from)."""
    return _run_config(_sources(config_file, None, assignments))


def resolve(
    config_file: str | Path | None = None,
    run_overrides: dict | None = None,
    assignments: list[str] = (),
) -> ResolvedConfig:
    """Merge defaults, a config file, CLI options and `--set` assignments; validate everything.

    Precedence is by source, whatever the spelling of a key: dataclass defaults < the config
    file < the command's options (`run_overrides`: `--frontend`, `--start`, ...) < `--set`.
    Within one source a flat key (`[tracker] threshold2`) and its twin in the chosen plugin's
    table (`[tracker.klt] threshold2`) are one key: in a file the table's value wins; among
    `--set` assignments the later wins.
    """
    sources = _sources(config_file, run_overrides, assignments)
    run = _run_config(sources)
    dataset_cls, _ = registry.resolve_dataset(run.dataset)
    chosen = {
        "dataset": dataset_cls,
        "frontend": registry.get("frontends", run.frontend),
        "tracker": registry.get("trackers", run.tracker),
        "backend": registry.get("backends", run.backend),
    }
    given = [{name: _values(source, name, cls) for name, cls in chosen.items()} for source in sources]
    moved = [_move_to_run(values, source.where) for values, source in zip(given, sources)]
    run = _run_config(sources, moved)
    sections = {}
    for name, cls in chosen.items():
        values = {k: v for source_values in given for k, (_, v) in source_values[name].items()}
        sections[name] = build(cls.Config, values, f"{name}.{cls.name}")
    origin = " ".join([Path(config_file).name if config_file else "defaults"] + [f"--set {a}" for a in assignments])
    return ResolvedConfig(run=run, **sections, origin=origin)


def _move_to_run(given: dict[str, dict], where: str) -> dict[str, tuple[str, Any]]:
    """Take the MOVED_TO_RUN keys out of one source's [tracker] and [backend] values (as every
    config.toml written before they moved holds them) and return them as [run] values, which
    that source's own [run] overrides; two that disagree (the rig has one IMU) are an error
    naming both."""
    moved = {}
    for key in MOVED_TO_RUN:
        found = [given[section].pop(key) for section in ("tracker", "backend") if key in given[section]]
        if any(not _same(found[0][1], value) for _, value in found[1:]):
            places = ", ".join(f"{written} = {_toml_value(v)}" for written, v in found)
            raise ConfigError(f"{where}: {places}: the rig has one IMU; set run.{key} only")
        if found:
            moved[key] = found[0]
    return moved


def _same(a, b) -> bool:
    """Whether two values of one key are the same (numbers compared as numbers: 1 and 1.0)."""
    return repr(_as_numbers(a)) == repr(_as_numbers(b))


def _as_numbers(value):
    """A number, or a list of them, as floats (to compare values written 0 or 0.0); else as is."""
    try:
        return tuple(float(x) for x in value) if isinstance(value, (list, tuple)) else float(value)
    except (TypeError, ValueError):
        return value
