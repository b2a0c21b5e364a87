"""The plugin API from outside: `eas-vo list`, `eas-vo render`, and a third-party frontend
package installed and run through the CLI."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from eas_vo import registry
from eas_vo.cli import main

PLUGIN = Path(__file__).parent / "plugin_example"


def test_list_shows_every_plugin_with_description_and_keys(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for kind in registry.KINDS:
        assert f"{kind} (entry-point group eas_vo.{kind}):" in out
        for name, cls in registry.available(kind).items():
            assert f"  {name:10s} {cls.description}" in out
    assert "n=4000 sigma_px=1.0 beta=60.0 gamma=100.0" in out and "r=4 polarity='merged' dv_compatible=False" in out


def test_render_draws_a_gallery(short_sequence, tmp_path, capsys):
    out = tmp_path / "gallery.png"
    assert main(["render", "--dataset", str(short_sequence), "--frames", "3,20", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "2 frame(s) x 6 frontend(s)" in capsys.readouterr().out


def test_render_images_match_running_each_frontend(short_sequence):
    from eas_vo import config, pipeline
    from eas_vo.gallery import frontend_images

    names, images = frontend_images(str(short_sequence), [5], ["sits", "eas"])
    dataset = pipeline.open_dataset(str(short_sequence))
    for name in names:
        frontend = registry.get("frontends", name)(config.resolve(None, {"frontend": name}).frontend, dataset.camera)
        for sample in dataset.samples():
            image = frontend(sample)
            if sample.index == 5:
                break
        assert (image == images[(5, name)]).all(), name


def test_render_rejects_missing_frames(short_sequence, capsys):
    assert main(["render", "--dataset", str(short_sequence), "--frames", "3,9999", "--out", "x.png"]) == 2
    assert "frame 9999 does not exist" in capsys.readouterr().err


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    """The example plugin package, pip-installed into a private folder (nothing global changes)."""
    import shutil

    target = tmp_path_factory.mktemp("plugin-site")
    source = tmp_path_factory.mktemp("plugin-src") / "plugin"
    shutil.copytree(PLUGIN, source)  # pip builds in place: keep the repository clean
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target), str(source)],
        check=True,
        capture_output=True,
    )
    return target


def test_an_external_plugin_runs_through_the_cli(plugin_path, short_sequence, tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")]))
    listing = subprocess.run([sys.executable, "-m", "eas_vo", "list"], capture_output=True, text=True, env=env, check=True)
    assert "edges      Canny edges of the equalised frame (an example plugin)" in listing.stdout
    assert "config: low=50 high=150" in listing.stdout
    out = tmp_path / "edges"
    run = subprocess.run(
        [sys.executable, "-m", "eas_vo", "run", "--dataset", str(short_sequence), "--frontend", "edges",
         "--set", "frontend.high=120", "--out", str(out)],
        capture_output=True, text=True, env=env,
    )
    assert run.returncode == 0, run.stderr
    assert "edges+chain" in run.stdout and (out / "metrics.json").exists()
    assert 'high = 120' in (out / "config.toml").read_text()
    bad = subprocess.run([sys.executable, "-m", "eas_vo", "run", "--dataset", str(short_sequence), "--frontend", "edges",
                          "--set", "frontend.nope=1"], capture_output=True, text=True, env=env)
    assert bad.returncode == 2 and "unknown key frontend.nope; allowed keys: high, low" in bad.stderr
