"""The gyro's policy: when the backend reads the gyro on another clock, what the warnings name, and what the summary says read the gyro."""

import numpy as np
import pytest

from eas_vo import config, registry
from eas_vo.imu.fit import ImuAgreement
from eas_vo.imu.policy import GyroSetup, backend_gyro, disagreements, gyro_readers
from eas_vo.types import ImuSeries


def setup_of(cfg, tracker_uses_imu: bool = False, backend_uses_imu: bool | None = None) -> GyroSetup:
    """The policy's view of a resolved configuration (pipeline.runner.gyro_setup), with stand-ins
    for the tracker and backend a run would build."""
    from types import SimpleNamespace

    from eas_vo.pipeline.runner import gyro_setup

    tracker, backend = registry.get("trackers", cfg.run.tracker), registry.get("backends", cfg.run.backend)
    backend_uses_imu = backend(cfg.backend).uses_imu if backend_uses_imu is None else backend_uses_imu
    parts = SimpleNamespace(
        frontend=registry.get("frontends", cfg.run.frontend),
        tracker=SimpleNamespace(uses_imu=tracker_uses_imu, imu_use=tracker.imu_use, reads_images=tracker.reads_images),
        backend=SimpleNamespace(uses_imu=backend_uses_imu, imu_use=backend.imu_use),
    )
    return gyro_setup(cfg, parts)


@pytest.mark.parametrize(
    "backend, frontend, at_limit, reclocked",
    [
        ("gtsam", "eas", False, True),
        ("chain", "eas", False, False),
        ("gtsam", "eas", True, False),
        ("gtsam", "ts", False, False),
    ],
)
def test_the_gyro_is_reclocked_only_for_a_backend_that_reads_it_and_a_shift_found(
    backend, frontend, at_limit, reclocked
):
    """A check that found the gyro 12 ms late, the configured offset 5 ms: with auto, a backend
    that reads the IMU gets it 12 ms earlier, read at 17 ms, and no clock warning; one that
    does not (chain), or a shift on the search's edge, keeps the configured clock and warns;
    with images that show the past (ts) the shift is their lag: the clock is kept, none suggested."""
    cfg = config.resolve(
        "best",
        {"backend": backend, "frontend": frontend},
        ["run.imu_time_offset_s=0.005", "run.imu_time_offset_auto=true"],
    )
    setup = setup_of(cfg)
    found = ImuAgreement(np.eye(3), 100, 90, 0.6, 0.012, at_limit, 0.004, 0.008, 0.5)
    imu = ImuSeries(np.arange(0.0, 1.0, 0.005), np.zeros((200, 3)), np.ones((200, 3)))
    given, offset = backend_gyro(setup, imu, found)
    if reclocked:
        np.testing.assert_allclose(given.t, imu.t - 0.012)
        assert offset == pytest.approx(0.017) and disagreements(setup, found, reclocked=True) == []
    else:
        assert given is imu and offset == 0.005
        said = disagreements(setup, found, reclocked=False)
        limit = "at least " if at_limit else ""
        assert len(said) == 1 and f"read {limit}12.0 ms later" in said[0]
        if frontend == "ts":
            assert "the ts images show the past, so this is taken for their lag" in said[0]
            assert "run.imu_time_offset_s" not in said[0]
        else:
            assert f"run.imu_time_offset_s = {limit}0.0170 would match them, not 0.005" in said[0]


@pytest.mark.parametrize(
    "tracker,backend,retracked,says",
    [
        (
            "cmax",
            "chain",
            False,
            "by the cmax tracker as the start of its search for each rotation (the rotations measured from the events)",
        ),
        (
            "klt",
            "gtsam",
            False,
            "by the klt tracker as the start of its search for each rotation (the rotations measured "
            "from the eas images) and by the gtsam backend as measurements fused with the tracker's rotations",
        ),
        ("klt", "gtsam", True, "by the gtsam backend as measurements fused with the tracker's rotations"),
        ("klt", "chain", True, None),
    ],
)
def test_the_summary_says_what_the_gyro_is_used_for(tracker, backend, retracked, says):
    """An event-only run's gyro is its tracker's start point, not a measurement: the summary
    says so from each plugin's own word (Tracker.imu_use, Backend.imu_use)."""
    from types import SimpleNamespace

    setup = setup_of(
        config.resolve(None, {"tracker": tracker, "backend": backend}),
        tracker_uses_imu=True,
        backend_uses_imu=backend == "gtsam",
    )
    assert gyro_readers(setup, SimpleNamespace(contradicts=False), retracked) == says
    assert gyro_readers(setup, SimpleNamespace(contradicts=True), retracked) is None
    assert gyro_readers(setup, None, retracked) is None


@pytest.mark.parametrize(
    "tracker,frontend,names",
    [("cmax", "eas", "the time the events show"), ("klt", "histeq", "the time the histeq images show")],
)
def test_the_imu_clock_warning_names_what_the_tracker_measured(tracker, frontend, names):
    cfg = config.resolve(None, {"tracker": tracker, "frontend": frontend})
    (said,) = disagreements(
        setup_of(cfg), ImuAgreement(np.eye(3), 100, 90, 0.6, 0.012, False, 0.004, 0.008, 0.5), reclocked=False
    )
    assert f"the IMU's clock, or {names}, is off by that" in said and "no_image" not in said
