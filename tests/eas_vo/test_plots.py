"""Figures are drawn without touching the process's matplotlib state."""

import matplotlib
import numpy as np

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
    rows = [{"dataset": "d", "method": "klt+chain", "frontend": f, "sweep": "", "status": "ok", "ape_mean_rad": v}
            for f, v in (("original", 0.4), ("eas", 0.04))]
    plots.plot_ape_bars(tmp_path / "bars.png", rows)
    plots.plot_ape_time(tmp_path / "time.png", {("d", "eas"): (np.arange(5.0), np.linspace(0, 0.1, 5))})


def test_the_rotation_plot_shows_where_tracking_was_weak_or_lost_and_where_loops_closed():
    from types import SimpleNamespace

    from eas_vo.evaluation import rotation_errors
    from eas_vo.geometry.rotations import rotvec_to_matrix
    from eas_vo.types import FrameRecord, PoseSeries, RelativeRotation

    statuses = ["first", "ok", "weak", "weak", "ok", "lost", "ok", "weak", "ok", "ok"]
    t = 0.1 * np.arange(len(statuses))
    records = [FrameRecord(k, t[k], 0, 0, s, False) for k, s in enumerate(statuses)]
    edges = [RelativeRotation(0, 6, np.eye(3), loop=True), RelativeRotation(1, 6, np.eye(3), loop=True),
             RelativeRotation(2, 8, np.eye(3), loop=True), RelativeRotation(8, 9, np.eye(3)),
             RelativeRotation(3, 12, np.eye(3), loop=True)]  # a frame the run does not have: not drawn
    R_w_c = np.stack([rotvec_to_matrix(np.array([0.0, 0.0, 0.01 * k])) for k in range(len(t))])  # 0.01 rad per frame
    t_gt = np.linspace(0.15, 0.95, 9)  # ground truth from frame 2 on
    gt = PoseSeries(t_gt, np.zeros((9, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (9, 1)))
    for errors in (None, rotation_errors(t, R_w_c, gt)):
        result = SimpleNamespace(t=t, R_w_c=R_w_c, errors=errors, records=records, edges=edges, metrics={})
        axes = plots.rotation_figure(result).axes
        for ax in axes:  # the runs of weak frames (2-3, 7) and the lost frame (5), in every panel
            shaded = {status: [] for status in plots.STATUS_COLOURS}
            for collection in ax.collections:
                colour = collection.get_facecolor()[0][:3]
                status = next(s for s, c in plots.STATUS_COLOURS.items() if np.allclose(matplotlib.colors.to_rgb(c), colour))
                shaded[status] += [tuple(np.round(p.get_extents().intervalx, 6)) for p in collection.get_paths()]
            assert shaded == {"weak": [(0.1, 0.3), (0.6, 0.7)], "lost": [(0.4, 0.5)]}, shaded
        marks = [line for line in axes[3].lines if line.get_label() != "error"]
        np.testing.assert_allclose([line.get_xdata()[0] for line in marks], [0.6, 0.8])  # loops closed at frames 6 and 8
        labels = set(axes[3].get_legend_handles_labels()[1])
        assert labels == {"weak", "lost", "loop closed"} | ({"error"} if errors is not None else set())
        if errors is not None:  # the error [deg] of frames 2-9, aligned at frame 2
            (curve,) = [line for line in axes[3].lines if line.get_label() == "error"]
            np.testing.assert_allclose(curve.get_xdata(), t[2:])
            np.testing.assert_allclose(curve.get_ydata(), np.degrees(0.01 * np.arange(8)), atol=1e-9)


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
