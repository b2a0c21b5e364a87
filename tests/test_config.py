"""Configuration: files, flags, --set, per-plugin tables, validation, round trip."""

import math

import pytest

from eas_vo.config import parse_set, resolve
from eas_vo.errors import ConfigError, EasVoError


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


def test_per_plugin_tables_apply_only_to_their_plugin(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[frontend.eas]\nbeta = 40.0\n[frontend.slice]\nn = 123\n")
    assert resolve(path, {"frontend": "eas"}).frontend.beta == 40.0
    assert resolve(path, {"frontend": "slice"}).frontend.n == 123


@pytest.mark.parametrize(
    "assignment,match",
    [
        ("frontend.bogus=1", "unknown key frontend.bogus"),
        ("frontend.n=abc", "frontend.n must be int"),
        ("frontend.n=0", "n = 0 is out of range"),
        ("tracker.threshold1=500", "threshold1 .* must not exceed threshold2"),
        ("nosection.x=1", "SECTION.KEY=VALUE"),
        ("run.frontend=nope", "unknown frontend 'nope'; installed: eas, histeq, original, sits, slice, ts"),
    ],
)
def test_invalid_values_are_rejected_with_the_key(assignment, match):
    with pytest.raises(EasVoError, match=match):
        resolve(None, {}, [assignment])


def test_set_parses_toml_values():
    assert parse_set("frontend.beta=40") == (["frontend", "beta"], 40)
    assert parse_set("run.dataset=some/folder") == (["run", "dataset"], "some/folder")
    assert parse_set("tracker.essential_method='ransac'") == (["tracker", "essential_method"], "ransac")


def test_resolved_config_round_trips_through_toml(tmp_path):
    cfg = resolve(None, {"frontend": "slice", "duration_s": 2.5}, ["tracker.threshold2=99"])
    path = tmp_path / "config.toml"
    path.write_text(cfg.to_toml())
    assert resolve(path) == cfg


def test_bundled_config_by_name():
    cfg = resolve("paper")
    assert cfg.run.frontend == "eas" and cfg.run.backend == "chain"


def test_bad_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[run\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        resolve(path)
