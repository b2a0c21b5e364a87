"""Configuration: files, flags, --set, per-plugin tables, validation, round trip."""

import math
import tomllib
from dataclasses import fields

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo import registry
from eas_vo.config import SECTIONS, parse_set, resolve
from eas_vo.errors import ConfigError, EasVoError
from helpers import hostile_number, hostile_settings


def test_defaults():
    cfg = resolve()
    assert (cfg.run.dataset, cfg.run.frontend, cfg.run.backend) == ("synthetic:default", "eas", "chain")
    assert cfg.run.duration_s == math.inf and cfg.frontend.n == 4000


def test_precedence_file_then_flags_then_set(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[run]\nfrontend = "slice"\nbackend = "chain"\n[frontend]\nn = 100\n[tracker]\nthreshold1 = 12\n')
    cfg = resolve(path, {"frontend": None}, ["frontend.n=300"])
    assert cfg.run.frontend == "slice" and cfg.frontend.n == 300 and cfg.tracker.threshold1 == 12
    cfg = resolve(path, {"frontend": "eas"}, [])
    assert cfg.run.frontend == "eas" and cfg.frontend.n == 100


def _spelled(dotted: str, value) -> str:
    """`tracker.klt.threshold2`, 150 -> the TOML that sets it."""
    table, key = dotted.rsplit(".", 1)
    return f"[{table}]\n{key} = {value}\n"


#: A family of spellings of one key: a plugin's key flat or in its table; the IMU's clock in
#: [run] or in the places older config files hold it.
SPELLINGS = {
    "threshold2": ("tracker", ["tracker.threshold2", "tracker.klt.threshold2"], 150, 100),
    "imu_time_offset_s": (
        "run",
        [
            "run.imu_time_offset_s",
            "tracker.imu_time_offset_s",
            "tracker.klt.imu_time_offset_s",
            "backend.chain.imu_time_offset_s",
        ],
        0.004,
        0.009,
    ),
}


@pytest.mark.parametrize(
    "key,in_file,in_set",
    [
        (key, in_file, in_set)
        for key, (_, spellings, _, _) in SPELLINGS.items()
        for in_file in [None, *spellings]
        for in_set in [None, *spellings]
    ],
)
def test_precedence_is_by_source_whatever_the_spelling(tmp_path, key, in_file, in_set):
    """--set beats the file and the file beats the defaults, flat key or plugin table alike."""
    section, _, file_value, set_value = SPELLINGS[key]
    path = tmp_path / "c.toml"
    path.write_text(_spelled(in_file, file_value) if in_file else "")
    cfg = resolve(path, {}, [f"{in_set}={set_value}"] if in_set else [])
    default = getattr(getattr(resolve(), section), key)
    assert getattr(getattr(cfg, section), key) == (set_value if in_set else file_value if in_file else default)


@pytest.mark.parametrize("in_file", [False, True])
@pytest.mark.parametrize("in_options", [False, True])
@pytest.mark.parametrize("in_set", [False, True])
def test_precedence_of_the_file_the_options_and_set(tmp_path, in_file, in_options, in_set):
    path = tmp_path / "c.toml"
    path.write_text("[run]\nstart_s = 1.0\n" if in_file else "")
    cfg = resolve(path, {"start_s": 2.0 if in_options else None}, ["run.start_s=3.0"] if in_set else [])
    assert cfg.run.start_s == (3.0 if in_set else 2.0 if in_options else 1.0 if in_file else 0.0)


@pytest.mark.parametrize(
    "text",
    [
        "[tracker]\nmax_corners = 20\n[tracker.klt]\nmax_corners = 10\n",
        "[tracker.klt]\nmax_corners = 10\n[tracker]\nmax_corners = 20\n",
    ],
)
def test_in_a_file_the_plugins_table_wins_over_the_flat_key_whatever_their_order(tmp_path, text):
    path = tmp_path / "c.toml"
    path.write_text(text)
    assert resolve(path).tracker.max_corners == 10
    assert (
        resolve(path, {}, ["tracker.max_corners=30"]).tracker.max_corners == 30
    )  # --set over the file, either spelling
    path.write_text("[frontend]\nn = 3000\n[frontend.slice]\nn = 5000\n")  # another plugin's table: not read
    assert resolve(path, {"frontend": "eas"}).frontend.n == 3000
    assert resolve(path, {"frontend": "slice"}).frontend.n == 5000


@pytest.mark.parametrize(
    "first,then", [("tracker.threshold2", "tracker.klt.threshold2"), ("tracker.klt.threshold2", "tracker.threshold2")]
)
def test_among_set_assignments_the_later_wins_whatever_the_spelling(first, then):
    assert resolve(None, {}, [f"{first}=120", f"{then}=130"]).tracker.threshold2 == 130


def test_the_lenient_option_is_an_option_that_set_overrides(short_sequence):
    from argparse import Namespace

    from eas_vo.cli.options import set_assignments

    args = Namespace(assignments=["dataset.lenient=false"], lenient=True)
    assert not resolve(None, {"dataset": str(short_sequence)}, set_assignments(args)).dataset.lenient
    args = Namespace(assignments=[], lenient=True)
    assert resolve(None, {"dataset": str(short_sequence)}, set_assignments(args)).dataset.lenient


def test_per_plugin_tables_apply_only_to_their_plugin(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[frontend.eas]\nbeta = 40.0\n[frontend.slice]\nn = 123\n")
    assert resolve(path, {"frontend": "eas"}).frontend.beta == 40.0
    assert resolve(path, {"frontend": "slice"}).frontend.n == 123


@pytest.mark.parametrize(
    "assignment,match",
    [
        ("frontend.bogus=1", "unknown key frontend.eas.bogus"),
        ("frontend.n=abc", "frontend.eas.n must be int"),
        ("frontend.n={a=1}", "frontend.eas.n must be int"),  # a table where a number goes: the key's own message
        ("frontend.n=0", "frontend.eas.n = 0 is out of range"),
        ("tracker.threshold1=500", "tracker.klt.threshold1 .* must not exceed threshold2"),
        ("nosection.x=1", "SECTION.KEY=VALUE"),
        ("run.frontend=nope", "unknown frontend 'nope'; installed: "),
        ("run.tracker=nope", "unknown tracker 'nope'; installed: "),
        ("frontend.eass.n=0", "unknown table frontend.eass: not an installed frontend plugin"),
        ("run.duration_s=0", r"run.duration_s = 0.0 is out of range \(0.0, inf\]"),
    ],
)
def test_invalid_values_are_rejected_with_the_key(assignment, match):
    with pytest.raises(EasVoError, match=match):
        resolve(None, {}, [assignment])


def test_an_unknown_plugin_lists_what_the_registry_reports():
    with pytest.raises(EasVoError) as info:
        resolve(None, {"frontend": "nope"})
    assert str(info.value).endswith("installed: " + ", ".join(registry.available("frontends")))


def test_set_parses_toml_values():
    assert parse_set("frontend.beta=40") == (["frontend", "beta"], 40)
    assert parse_set("run.dataset=some/folder") == (["run", "dataset"], "some/folder")
    assert parse_set("tracker.essential_method='ransac'") == (["tracker", "essential_method"], "ransac")


def test_resolved_config_round_trips_through_toml(tmp_path):
    cfg = resolve(None, {"frontend": "slice", "duration_s": 2.5}, ["tracker.threshold2=99"])
    path = tmp_path / "config.toml"
    path.write_text(cfg.to_toml())
    assert resolve(path) == cfg


@pytest.mark.parametrize("name", ["paper", "best"])
@pytest.mark.parametrize("backend", ["chain", "gtsam"])
def test_bundled_configs_round_trip_exactly(tmp_path, name, backend):
    cfg = resolve(name, {"backend": backend})
    path = tmp_path / "config.toml"
    path.write_text(cfg.to_toml())
    assert resolve(path) == cfg and hash(resolve(path)) == hash(cfg)  # frozen all the way down (tuples, not lists)


def test_bundled_config_by_name():
    cfg = resolve("paper")
    assert cfg.run.frontend == "eas" and cfg.run.backend == "chain"


def test_a_resolved_config_says_what_made_it_without_that_being_part_of_it(tmp_path):
    assert resolve().origin == "defaults"
    cfg = resolve("paper", {}, ["tracker.threshold2=99"])
    assert cfg.origin == "paper --set tracker.threshold2=99"
    path = tmp_path / "config.toml"
    path.write_text(cfg.to_toml())
    assert resolve(path).origin == "config.toml" and resolve(path) == cfg


def test_bad_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[run\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        resolve(path)


def resolved_value(cfg, section: str, key: str):
    value = getattr(getattr(cfg, section), key)
    return list(value) if isinstance(value, tuple) else value


@hostile_settings()
@given(
    key=st.sampled_from(
        [
            "frontend.n",
            "frontend.beta",
            "frontend.sigma_px",
            "tracker.threshold1",
            "tracker.max_corners",
            "run.start_s",
            "run.duration_s",
            "backend.x",
            "nosuch.key",
            "frontend",
        ]
    ),
    value=st.one_of(hostile_number(), st.text(max_size=8)),
)
def test_hostile_set_values_are_one_line_errors_or_taken_exactly(key, value):
    try:
        cfg = resolve(None, {}, [f"{key}={value}"])
    except EasVoError as exc:
        assert "\n" not in str(exc)
        return
    keys, parsed = parse_set(f"{key}={value}")
    assert resolved_value(cfg, *keys) == parsed  # accepted: the value given is the value used


@hostile_settings()
@given(st.binary(max_size=300))
def test_hostile_config_files_are_one_line_errors_or_taken_exactly(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("c") / "c.toml"
    path.write_bytes(data)
    try:
        cfg = resolve(path)
    except EasVoError as exc:
        assert "\n" not in str(exc).strip()
        return
    for section, table in tomllib.loads(data.decode("utf-8-sig")).items():  # accepted: every flat key was taken
        assert section in SECTIONS
        for key, value in table.items():
            if not isinstance(value, dict):
                assert resolved_value(cfg, section, key) == value


@pytest.mark.parametrize("data", [b"\xef", b"\xef\xbb", b"[run]\nstart_s = 1.0\n\xef"])
def test_a_config_cut_inside_a_byte_order_mark_or_a_character_is_refused(tmp_path, data):
    """Not read as an empty file: Python's utf-8-sig text reader takes a lone b"\\xef" for the start of a mark."""
    path = tmp_path / "c.toml"
    path.write_bytes(data)
    with pytest.raises(ConfigError, match=rf"^{path}: invalid TOML: 'utf-8' codec can't decode"):
        resolve(path)


def test_a_config_written_before_the_imu_moved_to_run_still_resolves(tmp_path):
    """config.toml files written before run.imu_* existed hold the IMU's place in [tracker]
    and [backend] (or the chosen plugin's table): it moves to [run] unless the same source's
    [run] says otherwise, and a later source (--set) wins however it spells the key; two old
    places in one source that disagree are one error naming both."""
    old = tmp_path / "old.toml"
    text = (
        '[run]\ntracker = "klt"\nbackend = "gtsam"\n[tracker]\nimu_rotvec_cam = [0.0, 0.0, 1.5]\n'
        "imu_time_offset_s = 0.004\n[backend.gtsam]\nimu_rotvec_cam = [0, 0, 1.5]\nimu_time_offset_s = 0.004\n"
    )
    old.write_text(text)
    cfg = resolve(old)
    assert cfg.run.imu_rotvec_cam == (0.0, 0.0, 1.5) and cfg.run.imu_time_offset_s == 0.004
    assert not any("imu_" in f.name for f in fields(cfg.tracker))
    # what the run's IMU warning asks for wins over the old places; other plugins' tables are not read
    assert resolve(old, assignments=["run.imu_time_offset_s=0.009"]).run.imu_time_offset_s == 0.009
    assert resolve(old, assignments=["backend.gtsam.imu_time_offset_s=0.005"]).run.imu_time_offset_s == 0.005
    assert resolve(old, assignments=["backend.chain.imu_time_offset_s=0.5"]).run.imu_time_offset_s == 0.004
    old.write_text(text.replace('tracker = "klt"\n', 'tracker = "klt"\nimu_time_offset_s = 0.001\n'))
    assert resolve(old).run.imu_time_offset_s == 0.001  # the file's [run] over its old places
    old.write_text(text.replace("imu_time_offset_s = 0.004\n", "imu_time_offset_s = 0.005\n", 1))
    with pytest.raises(
        ConfigError,
        match=rf"^{old}: tracker.imu_time_offset_s = 0.005, backend.gtsam.imu_time_offset_s = "
        r"0.004: the rig has one IMU; set run.imu_time_offset_s only$",
    ):
        resolve(old, assignments=["run.imu_time_offset_s=0.009"])


@pytest.mark.parametrize(
    "text,says",
    [
        ('frontend = "eas"\n', 'frontend must be a table \\(\\[frontend\\] and its keys\\), found "eas"'),
        ("run = 5\n", "run must be a table .*, found 5"),
        ('run = "x"\n', 'run must be a table .*, found "x"'),
        ('[[run]]\nfrontend = "eas"\n', r"run must be a table .*, found an array of tables"),
        ('dataset = "x"\n', 'dataset must be a table .*, found "x"'),
        ("[tracker]\nklt = 5\n", r"tracker.klt must be a table \(the klt tracker's keys, \[tracker.klt\]\), found 5"),
        ("[[tracker.klt]]\nmax_corners = 5\n", r"tracker.klt must be a table .*, found an array of tables"),
        ("[frontend]\neas = [1, 2]\n", r"frontend.eas must be a table .*, found \[1, 2\]"),
    ],
)
def test_a_section_or_plugin_table_that_is_not_one_names_the_file_and_key(tmp_path, text, says):
    from eas_vo.config import run_section

    path = tmp_path / "c.toml"
    path.write_text(text)
    for read in (resolve, run_section):  # run, export, render; compare's [run]
        with pytest.raises(ConfigError, match=rf"^{path}: {says}$"):
            read(path)


def test_a_set_plugin_table_that_is_not_one_names_the_assignment():
    with pytest.raises(ConfigError, match=r"^--set tracker.klt=5: tracker.klt must be a table .*, found 5$"):
        resolve(None, {}, ["tracker.klt=5"])


def test_a_byte_order_mark_is_read_past(tmp_path):
    path = tmp_path / "c.toml"
    path.write_bytes(b'\xef\xbb\xbf[run]\nfrontend = "slice"\n')
    assert resolve(path).run.frontend == "slice"


@pytest.mark.parametrize("value", ['"abc"', "5", "true", "{a = 1}", "[1, 2]", '[1, "a", 3]'])
def test_a_vector_key_says_what_it_expects(value):
    with pytest.raises(ConfigError, match=r"^run.imu_rotvec_cam = .*; expected an array of 3 finite numbers \[rad\]$"):
        resolve(None, {}, [f"run.imu_rotvec_cam={value}"])


def test_a_vector_key_its_config_does_not_check_is_still_refused_unless_an_array():
    from dataclasses import dataclass

    from eas_vo.config import build

    @dataclass(frozen=True)
    class Unchecked:
        offsets: tuple = (0.0, 0.0)

    assert build(Unchecked, {"offsets": [1, 2]}, "plugin").offsets == (1, 2)
    with pytest.raises(ConfigError, match=r"^plugin.offsets must be an array, e.g. \[0.0, 0.0\], got 'abc'$"):
        build(Unchecked, {"offsets": "abc"}, "plugin")


@pytest.mark.parametrize("given", [None, "eas", "original"])
def test_a_tracker_that_reads_no_images_runs_with_the_none_frontend(given):
    cfg = resolve(None, {"tracker": "cmax", "frontend": given})
    assert cfg.run.frontend == "no_image" and not registry.get("frontends", "no_image").makes_images
    assert 'frontend = "no_image"' in cfg.to_toml()
    assert resolve(None, {"tracker": "klt", "frontend": given}).run.frontend == (given or "eas")
