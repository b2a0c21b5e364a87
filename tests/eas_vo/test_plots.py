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
