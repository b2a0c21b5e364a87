"""The plugin contracts from outside: `eas-vo list`, the plugin guide's four example plugins
(extracted from docs/plugins.md at test time) and a pip-installed plugin package, each run
through the CLI in a subprocess with nothing installed globally."""

import csv
import json
import os
import re
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from eas_vo import registry
from eas_vo.cli.main import main
from helpers import REPOSITORY, run_eas_vo

PLUGIN_PACKAGE = REPOSITORY / "tests" / "plugin_example"


def test_list_shows_every_plugin_with_description_and_keys(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for kind in registry.KINDS:
        assert f"{kind} (entry-point group eas_vo.{kind}):" in out
        for name, cls in registry.available(kind).items():
            assert f"  {name:10s} {cls.description}" in out
    assert "n=4000 sigma_px=1.0 beta=60.0 gamma=100.0" in out and "r=4 polarity='merged' dv_compatible=False" in out
    assert out.startswith("run (every run") and "imu_rotvec_cam=(0.0, 0.0, 0.0) imu_time_offset_s=0.0" in out


def readme_plugin_guide() -> tuple[str, dict]:
    """The plugin guide (docs/plugins.md, before its first section): its Python blocks joined
    into one module, and its TOML block."""
    section = (REPOSITORY / "docs" / "plugins.md").read_text().split("\n## ")[0]
    python = re.findall(r"```python\n(.*?)```", section, re.S)
    toml = re.findall(r"```toml\n(.*?)```", section, re.S)
    assert len(python) == 4 and len(toml) == 1, "the plugin guide holds one example per kind and their registration"
    return "\n\n".join(python), tomllib.loads(toml[0])


def install_privately(folder, dist: str, module: str, source: str, entry_points: dict) -> None:
    """Make `module` and its entry points importable from `folder` alone (a dist-info, as pip writes)."""
    (folder / f"{module}.py").write_text(source)
    info = folder / f"{dist}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "".join(
            f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n"
            for group, eps in entry_points.items()
        )
    )


def write_npz(dataset, path) -> None:
    """A recording in the plugin guide's .npz layout (docs/plugins.md)."""
    gt = dataset.ground_truth
    frames = np.stack([dataset.load_frame(k) for k in range(len(dataset.frame_times()))])
    np.savez(
        path,
        frames=frames,
        frame_times=dataset.frame_times(),
        events=np.asarray(dataset.events()),
        K=dataset.camera.K,
        gt_t=gt.t,
        gt_p_w_c=gt.p_w_c,
        gt_q_w_c=gt.q_w_c,
    )


def test_the_readme_example_plugins_run_through_the_cli(short_sequence, tmp_path):
    source, pyproject = readme_plugin_guide()
    entry_points = pyproject["project"]["entry-points"]
    assert set(entry_points) == {f"eas_vo.{kind}" for kind in registry.KINDS}
    site = tmp_path / "site"
    site.mkdir()
    install_privately(site, "eas_vo_example", "eas_vo_example", source, entry_points)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))

    listing = run_eas_vo("list", env=env)
    assert listing.returncode == 0, listing.stderr
    for eps in entry_points.values():
        for name in eps:
            assert f"\n  {name:10s} " in listing.stdout
    assert "config: min_inliers=20" in listing.stdout and "config: features=1000 threshold_px=1.0" in listing.stdout

    recording = tmp_path / "recording.npz"  # no plugin prefix: the npz plugin claims the suffix
    write_npz(registry.open_dataset(str(short_sequence)), recording)
    out = tmp_path / "run"
    run = run_eas_vo(
        "run",
        "--dataset",
        str(recording),
        "--frontend",
        "sobel",
        "--tracker",
        "orbmatch",
        "--backend",
        "trusted_chain",
        "--set",
        "backend.min_inliers=30",
        "--out",
        str(out),
        env=env,
    )
    assert run.returncode == 0, run.stderr
    assert "sobel+orbmatch+trusted_chain" in run.stdout and "average APE" in run.stdout
    assert "min_inliers = 30" in (out / "config.toml").read_text()
    frames = (out / "frames.csv").read_text().splitlines()
    assert len(frames) == 1 + len(np.load(recording)["frame_times"]) and ",ok," in frames[2]

    bad = run_eas_vo("run", "--dataset", str(recording), "--frontend", "sobel", "--set", "frontend.nope=1", env=env)
    assert (
        bad.returncode == 1
        and bad.stderr.strip() == "eas-vo: error: unknown key frontend.sobel.nope; allowed keys: blur_px"
    )


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory):
    """tests/plugin_example pip-installed into a private folder (nothing global changes)."""
    import shutil

    target = tmp_path_factory.mktemp("plugin-site")
    source = tmp_path_factory.mktemp("plugin-src") / "plugin"
    shutil.copytree(PLUGIN_PACKAGE, source)  # pip builds in place: keep the repository clean
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target), str(source)],
        check=True,
        capture_output=True,
    )
    return target


def with_site(folder) -> dict:
    """The environment with `folder` first on PYTHONPATH."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(folder), os.environ.get("PYTHONPATH")])))


def still_ape_rad(run_folder) -> float:
    """The average APE of a camera that never turns: the ground truth's mean angle from its first frame."""
    q = np.loadtxt(run_folder / "groundtruth.tum")[:, 4:8]
    return float(np.mean(2 * np.arccos(np.clip(np.abs(q @ q[0]), 0.0, 1.0))))


def test_a_pip_installed_plugin_runs_through_the_cli(plugin_site, short_sequence, tmp_path):
    env = with_site(plugin_site)
    listing = run_eas_vo("list", env=env)
    assert "edges      Canny edges of the equalised frame (an example plugin)" in listing.stdout
    assert "config: low=50 high=150" in listing.stdout
    out = tmp_path / "edges"
    run = run_eas_vo(
        "run",
        "--dataset",
        str(short_sequence),
        "--frontend",
        "edges",
        "--set",
        "frontend.high=120",
        "--out",
        str(out),
        env=env,
    )
    assert run.returncode == 0, run.stderr
    assert "edges+klt+chain" in run.stdout and (out / "metrics.json").exists()
    assert "high = 120" in (out / "config.toml").read_text()


def test_a_pip_installed_event_tracker_follows_the_camera(plugin_site, short_sequence, tmp_path):
    """The package's tracker reads each sample's events (no image, no frontend) and its chained
    rotations follow the camera: far closer to the ground truth than a camera kept still."""
    env = with_site(plugin_site)
    listing = run_eas_vo("list", env=env)
    assert (
        "evflow     pan and tilt from the flow between consecutive event images (an example plugin)" in listing.stdout
    )
    out = tmp_path / "evflow"
    run = run_eas_vo("run", "--dataset", str(short_sequence), "--tracker", "evflow", "--out", str(out), env=env)
    assert run.returncode == 0, run.stderr
    assert "no_image+evflow+chain" in run.stdout
    with open(out / "frames.csv", newline="") as f:
        frames = list(csv.DictReader(f))
    assert [r["status"] for r in frames] == ["first"] + ["ok"] * (len(frames) - 1)
    assert min(int(r["events"]) for r in frames[1:]) >= 1000
    assert json.loads((out / "metrics.json").read_text())["ape_mean_rad"] < 0.5 * still_ape_rad(out)
