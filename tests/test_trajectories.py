"""The bundled configurations' trajectories against the ones recorded in
tests/support/trajectories/: on the embedded default sequence and on the real
`shapes_rotation` excerpt, 2 s each, through `eas-vo run`. A regression record: a change meant
to keep behaviour (a move, a refactoring) must leave them as they are; a change meant to move
them records them again with EAS_VO_RECORD_TRAJECTORIES=1 and says why in its commit.

"As they are" is the same timestamps and every rotation within SAME_RAD of its record: the
pose graph's last digits follow the processor's vector instructions and the numpy/gtsam
release (seen: 2e-12 rad between two x86-64 machines on the same wheels), while a change
of behaviour moves a 2-s trajectory by 1e-6 rad or more."""

import os

import numpy as np
import pytest

from eas_vo.cli.main import main
from eas_vo.geometry.rotations import geodesic_angle, matrices_from_quats
from eas_vo.io.tum import parse_tum
from helpers import REPOSITORY, SHAPES_ROTATION, require

RECORDED = REPOSITORY / "tests" / "support" / "trajectories"
#: How far [rad] a rotation may lie from its record and still be the same trajectory.
SAME_RAD = 1e-9
REAL = ["--dataset", str(SHAPES_ROTATION), "--frontend", "histeq", "--time-offset", "0.01"]
CASES = {
    "paper_synthetic": ["--config", "paper"],
    "best_synthetic": ["--config", "best"],
    "paper_real": ["--config", "paper", *REAL],
    "best_real": ["--config", "best", *REAL],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_a_bundled_configuration_gives_its_recorded_trajectory(name, tmp_path):
    if "--dataset" in CASES[name]:
        require(SHAPES_ROTATION)
    out = tmp_path / "run"
    assert main(["run", *CASES[name], "--duration", "2", "--quiet", "--out", str(out)]) == 0
    got = (out / "trajectory.tum").read_bytes()
    recorded = RECORDED / f"{name}.tum"
    if os.environ.get("EAS_VO_RECORD_TRAJECTORIES"):
        recorded.write_bytes(got)
    a, b = parse_tum(got, "now", ordered=False), parse_tum(recorded.read_bytes(), str(recorded), ordered=False)
    assert np.array_equal(a.t, b.t), f"{name}: other timestamps than {recorded.name} ({len(a.t)} against {len(b.t)})"
    apart = geodesic_angle(matrices_from_quats(a.q_w_c), matrices_from_quats(b.q_w_c)).max()
    assert apart <= SAME_RAD, f"{name}: the trajectory lies up to {apart:.3g} rad from {recorded.name}"
