"""Figures are drawn without touching the process's matplotlib state."""

import matplotlib
import numpy as np
import pytest

from eas_vo import plots


def test_plotting_leaves_the_backend_and_pyplot_alone(tmp_path):
    import matplotlib.pyplot as plt

    previous = matplotlib.get_backend()
    matplotlib.use("svg")  # a library user's choice, which drawing must not change
    before = plt.get_fignums()
    try:
        draw(tmp_path)
        assert matplotlib.get_backend() == "svg" and plt.get_fignums() == before
    finally:
        matplotlib.use(previous)
    for name in ("bars.png", "time.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def draw(tmp_path):
    rows = [
        {
            "dataset": "d",
            "method": "klt+chain",
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "ape_mean_rad": v,
            "nc_mean": 30.0,
        }
        for f, v in (("original", 0.4), ("eas", 0.04))
    ]
    plots.plot_ape_bars(tmp_path / "bars.png", rows)
    plots.plot_ape_time(
        tmp_path / "time.png", {("d", "klt+chain", "eas", ""): (np.arange(5.0), np.linspace(0, 0.1, 5))}
    )


def _compare_rows(frontends, methods=("klt+chain", "klt+gtsam")):
    """Rows as compare's table, APE and NC distinct per cell (k: the cell's index)."""
    cells = [(m, f) for m in methods for f in frontends]
    return [
        {
            "dataset": "d",
            "method": m,
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "ape_mean_rad": 0.01 * (k + 1),
            "nc_mean": 100.0 + k,
        }
        for k, (m, f) in enumerate(cells)
    ]


def _frontend_of(label: str) -> str:
    return label.split()[0]


def test_a_frontend_has_one_colour_in_every_compare_figure():
    """Bars, time curves and sweep lines: each built-in frontend in its fixed colour whatever
    the order or the set of frontends, a plugin's in the first spare one; no two alike."""
    from eas_vo.experiments.gallery import PAPER_COLOURS

    to_rgb = matplotlib.colors.to_rgb
    frontends = ["eas", "mine", "sits", "original", "histeq", "ts", "slice"]
    colours = plots.frontend_colours(frontends, PAPER_COLOURS)
    assert colours["mine"] == plots.SPARE_COLOURS[0] and len({to_rgb(c) for c in colours.values()}) == len(colours)
    assert plots.frontend_colours(["original", "eas"], PAPER_COLOURS) == PAPER_COLOURS  # the same without the plugin
    bars = plots.ape_bars_figure(_compare_rows(frontends), colours=colours)
    seen = {}
    for ax in bars.axes[:2]:
        for container in ax.containers:
            for patch in container:
                seen.setdefault(_frontend_of(container.get_label()), set()).add(to_rgb(patch.get_facecolor()))
    series = {
        ("d", m, f, ""): (np.arange(3.0), np.full(3, 0.1))
        for m in ("klt+chain", "klt+gtsam")
        for f in reversed(frontends)
    }
    for ax in plots.ape_time_figure(series, colours=colours).axes:
        for line in ax.lines:
            seen.setdefault(_frontend_of(line.get_label()), set()).add(to_rgb(line.get_color()))
    assert seen == {f: {to_rgb(colours[f])} for f in frontends}
    assert {f: to_rgb(c) for f, c in colours.items() if f in PAPER_COLOURS} == {
        "original": to_rgb("tab:blue"),
        "histeq": to_rgb("tab:orange"),
        "slice": to_rgb("tab:green"),
        "eas": to_rgb("tab:red"),
        "ts": to_rgb("tab:purple"),
        "sits": to_rgb("tab:brown"),
    }


def test_the_bars_carry_their_apes_and_ncs():
    """Two rows of panels, APE over NC, every bar labelled with its value (a failed cell's with
    "failed"); a method whose results are another's is not drawn, its name is under the one it equals."""
    rows = _compare_rows(["original", "eas", "slice"])[:3]
    rows[2] = {**rows[2], "status": "failed", "ape_mean_rad": None, "nc_mean": None}
    fig = plots.ape_bars_figure(rows, equal={("d", "klt+chain"): ["klt+gtsam"]})
    ape_ax, nc_ax = fig.axes[:2]
    texts = lambda ax: sorted(t.get_text() for t in ax.texts if t.get_text())  # noqa: E731
    assert texts(ape_ax) == ["0.010", "0.020", "failed"] and texts(nc_ax) == ["100", "101", "failed"]
    assert ape_ax.get_ylabel() == "average APE [rad]" and nc_ax.get_ylabel() == "average NC"
    assert [t.get_text() for t in nc_ax.get_xticklabels()] == ["klt+chain\n= klt+gtsam (same trajectories)"]


def test_ape_over_time_has_a_panel_per_method_and_draws_an_equal_one_once():
    t = np.arange(4.0)
    series = {
        ("d", m, f, ""): (t, 0.1 * t)
        for m in ("klt+chain", "klt+gtsam (keyframe_interval=3)")
        for f in ("original", "eas")
    }
    fig = plots.ape_time_figure(series, equal={("d", "klt+chain"): ["klt+gtsam"]})
    drawn = [ax for ax in fig.axes if ax.lines]
    assert [ax.get_title() for ax in drawn] == [
        "klt+chain\n= klt+gtsam (same trajectories)",
        "klt+gtsam (keyframe_interval=3)",
    ]
    assert [[line.get_label() for line in ax.lines] for ax in drawn] == [["original", "eas"]] * 2


def run_result(t, R_w_c, records, *, errors=None, edges=(), metrics=None, covariance=None, chain_covariance=None):
    """What plots.rotation_figure reads of a run: a RunResult's fields, given or empty."""
    from types import SimpleNamespace

    return SimpleNamespace(
        t=t,
        R_w_c=R_w_c,
        errors=errors,
        records=records,
        edges=list(edges),
        metrics=metrics or {},
        covariance=covariance,
        chain_covariance=chain_covariance,
    )


def test_the_rotation_plot_shows_where_tracking_was_weak_or_lost_and_where_loops_closed():
    from eas_vo.evaluation.ape import rotation_errors
    from eas_vo.geometry.rotations import rotvec_to_matrix
    from eas_vo.types import FrameRecord, PoseSeries, RelativeRotation

    statuses = ["first", "ok", "weak", "weak", "ok", "lost", "ok", "weak", "ok", "ok"]
    t = 0.1 * np.arange(len(statuses))
    records = [FrameRecord(k, t[k], 0, 0, s, False) for k, s in enumerate(statuses)]
    edges = [
        RelativeRotation(0, 6, np.eye(3), loop=True),
        RelativeRotation(1, 6, np.eye(3), loop=True),
        RelativeRotation(2, 8, np.eye(3), loop=True),
        RelativeRotation(8, 9, np.eye(3)),
        RelativeRotation(3, 12, np.eye(3), loop=True),
    ]  # a frame the run does not have: not drawn
    R_w_c = np.stack([rotvec_to_matrix(np.array([0.0, 0.0, 0.01 * k])) for k in range(len(t))])  # 0.01 rad per frame
    t_gt = np.linspace(0.15, 0.95, 9)  # ground truth from frame 2 on
    gt = PoseSeries(t_gt, np.zeros((9, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (9, 1)))
    for errors in (None, rotation_errors(t, R_w_c, gt)):
        result = run_result(t, R_w_c, records, errors=errors, edges=edges)
        axes = plots.rotation_figure(result).axes
        assert all(not ax.collections for ax in axes[:5])  # the panels themselves are not shaded (no covariance)
        strip = axes[5]  # the status row: the runs of weak frames (2-3, 7) and the lost frame (5), each on its line
        spans = {}
        for collection in strip.collections:
            colour = collection.get_facecolor()[0][:3]
            status = next(
                s for s, c in plots.STATUS_COLOURS.items() if np.allclose(matplotlib.colors.to_rgb(c), colour)
            )
            spans[status] = [
                np.round(p.get_extents().intervalx, 6).tolist() + [round(p.get_extents().y0, 6)]
                for p in collection.get_paths()
            ]
        assert spans == {"weak": [[0.1, 0.3, 0.1], [0.6, 0.7, 0.1]], "lost": [[0.4, 0.5, 1.1]]}, spans
        assert [label.get_text() for label in strip.get_yticklabels()] == ["weak (3)", "lost (1)"]
        omega = axes[3]  # angular velocity: the one consecutive edge measured (8 -> 9, no motion) at its middle
        estimates = [line for line in omega.lines if "estimate" in line.get_label()]
        assert len(estimates) == 3 and all(np.allclose(line.get_xdata(), [0.85]) for line in estimates)
        assert all(line.get_ydata().tolist() == [0.0] for line in estimates)
        assert len(omega.lines) == (3 if errors is None else 6)  # and the truth's, where it has one
        marks = [line for line in axes[4].lines if line.get_label() != "error"]
        np.testing.assert_allclose(
            [line.get_xdata()[0] for line in marks], [0.6, 0.8]
        )  # loops closed at frames 6 and 8
        labels = set(axes[4].get_legend_handles_labels()[1])
        assert labels == {"loop closed"} | ({"error"} if errors is not None else set())
        if errors is not None:  # the error [deg] of frames 2-9, aligned at frame 2
            (curve,) = [line for line in axes[4].lines if line.get_label() == "error"]
            np.testing.assert_allclose(curve.get_xdata(), t[2:])
            np.testing.assert_allclose(curve.get_ydata(), np.degrees(0.01 * np.arange(8)), atol=1e-9)


def test_the_rotation_plot_draws_a_band_of_one_sigma_about_each_estimated_angle():
    """The backend's covariance, else the chain's, as a band of +-1 sigma of roll, pitch and yaw
    about the estimate (at the identity: the sigmas about x, y, z), and the error it predicts
    (sqrt(trace)) beside the error; a frame whose sigma is huge (a frame the graph ties
    loosely) does not flatten the panel's curves."""
    from eas_vo.evaluation.ape import rotation_errors
    from eas_vo.types import FrameRecord, PoseSeries

    n = 6
    t = 0.1 * np.arange(n)
    records = [FrameRecord(k, t[k], 0, 0, "ok", False) for k in range(n)]
    R_w_c = np.tile(np.eye(3), (n, 1, 1))
    sigmas_rad = np.outer(np.arange(n), [0.001, 0.002, 0.003])  # growing along the chain
    chain = np.stack([np.diag(s**2) for s in sigmas_rad])
    graph = chain / 4  # half the sigmas
    gt = PoseSeries(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    for backend, expected in ((None, sigmas_rad), (graph, sigmas_rad / 2)):
        for errors in (None, rotation_errors(t, R_w_c, gt)):
            result = run_result(t, R_w_c, records, errors=errors, covariance=backend, chain_covariance=chain)
            axes = plots.rotation_figure(result).axes
            for k in range(3):
                (band,) = axes[k].collections
                assert band.get_label() == "estimate ± 1 sigma"
                upper = band.get_paths()[0].vertices[:, 1].max()
                assert upper == pytest.approx(np.degrees(expected[-1, k]), rel=1e-6)
            predicted = [line for line in axes[4].lines if line.get_label() == "predicted (RMS)"]
            if errors is None:
                assert predicted == []
            else:
                np.testing.assert_allclose(
                    predicted[0].get_ydata(), np.degrees(np.linalg.norm(expected, axis=1)), rtol=1e-9
                )
    huge = chain.copy()
    huge[3] = np.eye(3)  # 1 rad: 57 deg about a curve that spans 0.3 deg
    result = run_result(t, R_w_c, records, covariance=huge, chain_covariance=chain)
    low, high = plots.rotation_figure(result).axes[0].get_ylim()
    assert high - low < 20


def test_the_rotation_plot_title_gives_the_ground_truth_time_offset_it_was_measured_with():
    from eas_vo.evaluation.ape import rotation_errors
    from eas_vo.types import FrameRecord, PoseSeries

    t = 0.1 * np.arange(4)
    gt = PoseSeries(t, np.zeros((4, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (4, 1)))
    records = [FrameRecord(k, t[k], 0, 0, "ok", False) for k in range(4)]
    R_w_c = np.tile(np.eye(3), (4, 1, 1))
    for estimated, words in (
        (False, "ground truth time offset +10.0 ms"),
        (True, "ground truth time offset +10.0 ms (estimated)"),
    ):
        metrics = {"ape_mean_rad": 0.0, "nc_mean": 5.0, "time_offset_s": 0.01, "time_offset_estimated": estimated}
        result = run_result(t, R_w_c, records, errors=rotation_errors(t, R_w_c, gt), metrics=metrics)
        title = plots.rotation_figure(result, "eas + klt + chain (paper): a sequence").get_suptitle()
        assert title == f"eas + klt + chain (paper): a sequence\naverage APE 0.0000 rad, average NC 5.0, {words}"


def test_a_gallery_shows_each_sensor_pixel_up_to_its_widest(tmp_path):
    """At 100 dpi, a 346x260 image gets at least 346 figure pixels a column, not the DAVIS240's
    240; a 1280x720 one is shrunk to GALLERY_MAX_PX."""
    import cv2

    names = ["a", "b"]
    for height, width in ((180, 240), (260, 346), (720, 1280)):
        images = {(k, n): np.full((height, width), 100 * k, np.uint8) for k in (0, 1) for n in names}
        path = tmp_path / f"{width}.png"
        plots.plot_gallery(path, names, images, [0, 1])
        fig_h, fig_w = cv2.imread(str(path)).shape[:2]
        shown = min(width, plots.GALLERY_MAX_PX)
        assert len(names) * shown <= fig_w <= len(names) * (shown + plots.GALLERY_MARGIN_PX), (width, fig_w)
        assert 2 * shown * height / width <= fig_h, (height, fig_h)


def test_a_sweep_is_drawn_against_its_values_in_their_units():
    """compare's sweep figure: a title naming the dataset and method, the value axis labelled
    with what the value is and its unit (not the config key), a speed sweep on a log-2 axis
    ticked at the speeds themselves, an illumination sweep ticked at its lights; each frontend
    in the colour compare gives it."""
    from eas_vo.experiments.gallery import PAPER_COLOURS

    to_rgb = matplotlib.colors.to_rgb
    frontends = ["original", "eas"]
    colours = plots.frontend_colours(frontends, PAPER_COLOURS)
    speeds = {
        ("synthetic:default", "klt+chain", f): np.array([[1, 200, 0.1], [2, 190, 0.2], [4, 180, 0.4]])
        for f in frontends
    }
    fig = plots.sweep_figure("dataset.speed", speeds, colours)
    ape_ax, nc_ax = fig.axes[:2]
    assert fig.get_suptitle() == "Average APE and NC against camera speed: synthetic:default, klt+chain"
    for ax in (ape_ax, nc_ax):
        assert ax.get_xscale() == "log" and ax.xaxis.get_transform().base == 2
        assert list(ax.get_xticks()) == [1, 2, 4]
        assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "2", "4"]
        assert ax.get_xlabel().startswith("camera speed [x ") and "dataset.speed" not in ax.get_xlabel()
    assert {line.get_label(): to_rgb(line.get_color()) for line in ape_ax.lines} == {
        f: to_rgb(colours[f]) for f in frontends
    }
    lights = {
        k: np.array([[0.05, 0, 0.2], [0.1, 3, 0.2], [0.2, 14, 0.9], [0.5, 20, 0.5], [1, 28, 0.4]]) for k in speeds
    }
    ax = plots.sweep_figure("dataset.illumination", lights, colours).axes[0]
    assert ax.get_xscale() == "log" and ax.xaxis.get_transform().base == 10
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0.05", "0.1", "0.2", "0.5", "1"]
    assert ax.get_xlabel() == "illumination [x the scene's own light]"
    ax = plots.sweep_figure("tracker.max_corners", {("d", "m", "eas"): np.array([[100, 1, 0.2], [200, 2, 0.1]])}).axes[
        0
    ]
    assert ax.get_xscale() == "linear" and ax.get_xlabel() == "tracker.max_corners"  # an unknown key: named as swept
