"""Figures, drawn on matplotlib `Figure` objects rendered by the Agg canvas.

No pyplot: the process's matplotlib backend (a library user's interactive one, say)
is never changed, and no figure is left registered anywhere. Imported lazily:
matplotlib is only loaded when a figure is drawn.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from eas_vo.geometry.rotations import euler_zyx_deg


def _figure(**kwargs):
    """A new figure on its own Agg canvas (PNG output whatever the process's backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


#: How a frame's status is shaded in the tracking panel (ok and first: not at all).
STATUS_COLOURS = {"weak": "tab:orange", "lost": "tab:red"}
#: The widest a gallery shows an image [figure px]; the margin [px] around each for its labels.
GALLERY_MAX_PX, GALLERY_MARGIN_PX = 480, 24


def plot_rotation(path: str | Path, result, title: str = "") -> None:
    """rotation_figure, saved as PNG."""
    rotation_figure(result, title).savefig(path, dpi=110, format="png")


def rotation_figure(result, title: str = ""):
    """Estimated (aligned to ground truth at the first frame) and true roll/pitch/yaw over time,
    like the paper's Fig. 3, over a tracking panel: the rotation error [deg] per frame (with
    ground truth), weak and lost frames shaded (through every panel), loop closures marked at
    the frame that closed them. Without ground truth only the estimate is drawn."""
    t0 = result.t[0]
    errors = result.errors
    fig = _figure(figsize=(8, 8), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True, height_ratios=(1, 1, 1, 0.8))
    if errors is not None and errors.valid.any():
        _draw_euler(axes[:3], result.t[errors.valid] - t0, errors.R_w_c_aligned, errors.R_w_c_gt)
        axes[3].plot(result.t[errors.valid] - t0, np.degrees(errors.ape_rad), color="k", lw=0.9, label="error")
        axes[3].set_ylabel("error [deg]")
    else:
        _draw_euler(axes[:3], result.t - t0, result.R_w_c)
        axes[3].set_yticks([])
        axes[3].set_ylabel("tracking")
    _shade_statuses(axes, result.records, t0)
    for k, j in enumerate(sorted({e.j for e in result.edges if e.loop and 0 <= e.j < len(result.t)})):
        axes[3].axvline(result.t[j] - t0, color="tab:blue", lw=0.8, label="loop closed" if k == 0 else None)
    axes[0].legend(loc="best", fontsize="small")
    if axes[3].get_legend_handles_labels()[0]:
        axes[3].legend(loc="upper left", fontsize="small", ncol=4)
    axes[3].grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    m = result.metrics
    if "ape_mean_rad" in m:
        title += f"\naverage APE {m['ape_mean_rad']:.4f} rad, average NC {m['nc_mean']:.1f}"
    fig.suptitle(title, fontsize="medium")
    return fig


def _shade_statuses(axes, records, t0: float) -> None:
    """Shade each run of consecutive weak (or lost) frames in every axis, from the previous
    frame's time to its own (the interval its measurement covers): one collection per status
    and axis, labelled in the last."""
    runs = {status: [] for status in STATUS_COLOURS}  # (start [s], width [s]) per status
    for status, run in itertools.groupby(zip(records, records[1:]), key=lambda pair: pair[1].status):
        run = list(run)
        if status in runs:
            start, end = run[0][0].t, run[-1][1].t  # from the frame before the run to its last
            runs[status].append((start - t0, end - start))
    for status, spans in runs.items():
        for ax in axes:
            if spans:
                ax.broken_barh(spans, (0, 1), transform=ax.get_xaxis_transform(), color=STATUS_COLOURS[status],
                               alpha=0.2, lw=0, label=status if ax is axes[-1] else None)


def _draw_euler(column, t: np.ndarray, R_est: np.ndarray, R_gt: np.ndarray | None = None, labels: bool = True) -> None:
    """Roll, pitch, yaw [deg] over t [s] into three axes: the estimate over the ground truth (if any)."""
    est = np.unwrap(euler_zyx_deg(R_est), period=360, axis=0)
    gt = None if R_gt is None else np.unwrap(euler_zyx_deg(R_gt), period=360, axis=0)
    for k, (ax, name) in enumerate(zip(column, ("roll", "pitch", "yaw"))):
        if gt is not None:
            ax.plot(t, gt[:, k], color="0.2", lw=1.4, label="ground truth")
        ax.plot(t, est[:, k], color="tab:red", lw=1.0, label="estimate")
        ax.grid(alpha=0.3)
        if labels:
            ax.set_ylabel(f"{name} [deg]")


def plot_gallery(path: str | Path, names: list[str], images: dict, frame_indices: list[int], title: str = "") -> None:
    """A grid: one row per frame, one column per frontend (the paper's Fig. 1); each image at
    one figure pixel per sensor pixel, or shrunk (antialiased) to GALLERY_MAX_PX wide."""
    rows, cols = len(frame_indices), len(names)
    height, width = next((im.shape for im in images.values() if im is not None), (3, 4))
    shown_px = min(width, GALLERY_MAX_PX)
    interpolation = "nearest" if width <= GALLERY_MAX_PX else "antialiased"
    cell_w, cell_h = (shown_px + GALLERY_MARGIN_PX) / 100, (shown_px * height / width + GALLERY_MARGIN_PX) / 100  # [in] at 100 dpi
    fig = _figure(figsize=(cell_w * cols, cell_h * rows + 0.4), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    for r, k in enumerate(frame_indices):
        for c, name in enumerate(names):
            ax = axes[r][c]
            image = images[(k, name)]
            if image is None:
                ax.text(0.5, 0.5, "needs frames", ha="center", va="center", fontsize="small")
            else:
                ax.imshow(image, cmap="gray", vmin=0, vmax=255, interpolation=interpolation)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(name, fontsize="medium")
            if c == 0:
                ax.set_ylabel(f"frame {k}", fontsize="small")
    if title:
        fig.suptitle(title, fontsize="medium")
    fig.savefig(path, dpi=100, format="png")


def plot_ape_bars(path: str | Path, rows: list[dict]) -> None:
    """Average APE per source type (bars) and method, tracker+backend (colours), one panel per
    dataset; `rows` as compare.table_rows makes them."""
    ok = [r for r in rows if r["status"] == "ok" and r["ape_mean_rad"] is not None]
    datasets = list(dict.fromkeys(r["dataset"] for r in rows))
    backends = list(dict.fromkeys(r["method"] for r in rows))
    sources = list(dict.fromkeys(r["frontend"] + (f"\n{r['sweep']}" if r["sweep"] else "") for r in rows))
    panel_width = max(5.0, 0.8 * len(sources) * len(backends) + 2.0)
    fig = _figure(figsize=(panel_width * len(datasets), 3.8), layout="constrained")
    axes = fig.subplots(1, len(datasets), squeeze=False)
    width = 0.8 / max(1, len(backends))
    for ax, dataset in zip(axes[0], datasets):
        for b, backend in enumerate(backends):
            values = []
            for source in sources:
                match = [r for r in ok if r["dataset"] == dataset and r["method"] == backend
                         and r["frontend"] + (f"\n{r['sweep']}" if r["sweep"] else "") == source]
                values.append(match[0]["ape_mean_rad"] if match else np.nan)
            ax.bar(np.arange(len(sources)) + b * width, values, width, label=backend)
        ax.set_xticks(np.arange(len(sources)) + width * (len(backends) - 1) / 2, sources, fontsize="small")
        ax.set_ylabel("average APE [rad]")
        ax.set_title(Path(dataset.rstrip("/")).name or dataset, fontsize="medium")
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].legend(fontsize="small")
    fig.savefig(path, dpi=110, format="png")


def plot_ape_time(path: str | Path, series: dict) -> None:
    """APE over time: {(dataset, label): (t, ape)}, one panel per dataset, a line per label."""
    datasets = list(dict.fromkeys(d for d, _ in series))
    fig = _figure(figsize=(8, 3 * max(1, len(datasets))), layout="constrained")
    axes = fig.subplots(len(datasets), 1, squeeze=False)
    for ax, dataset in zip(axes[:, 0], datasets):
        for (d, label), (t, ape) in series.items():
            if d == dataset:
                ax.plot(t, ape, lw=1.0, label=label)
        ax.set_title(Path(dataset.rstrip("/")).name or dataset, fontsize="medium")
        ax.set_ylabel("APE [rad]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small", ncol=3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.savefig(path, dpi=110, format="png")


def plot_sweep(path: str | Path, key: str, curves: dict) -> None:
    """Average APE and NC against a swept value: {(dataset, method, frontend): (n, 3) array of
    (value, NC, APE)}, a line per frontend (and method and dataset when there are several);
    a logarithmic value axis when the values span more than a decade."""
    fig = _figure(figsize=(11, 4), layout="constrained")
    ape_ax, nc_ax = fig.subplots(1, 2)
    several = {part: len({k[i] for k in curves}) > 1 for i, part in enumerate(("dataset", "method", "frontend"))}
    for (dataset, method, frontend), xy in curves.items():
        label = " ".join([frontend] + ([method] if several["method"] else []) + ([Path(dataset).name or dataset] if several["dataset"] else []))
        ape_ax.plot(xy[:, 0], xy[:, 2], "o-", lw=1.2, ms=4, label=label)
        nc_ax.plot(xy[:, 0], xy[:, 1], "o-", lw=1.2, ms=4, label=label)
    values = np.concatenate([xy[:, 0] for xy in curves.values()]) if curves else np.array([1.0])
    for ax, what in ((ape_ax, "average APE [rad]"), (nc_ax, "average NC")):
        if values.min() > 0 and values.max() > 10 * values.min():
            ax.set_xscale("log")
        ax.set_xlabel(key)
        ax.set_ylabel(what)
        ax.grid(alpha=0.3, which="both")
    ape_ax.set_yscale("log")
    ape_ax.legend(fontsize="small")
    fig.savefig(path, dpi=110, format="png")


def plot_euler_grid(path: str | Path, panels: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], title: str = "") -> None:
    """The paper's Fig. 3 for one sequence: a column per source, rows roll/pitch/yaw [deg],
    estimate (aligned at the first frame) over ground truth. `panels`: (source label,
    t [s], R_w_c ground truth (N, 3, 3), R_w_c estimate (N, 3, 3))."""
    fig = _figure(figsize=(2.6 * len(panels) + 0.8, 6.0), layout="constrained")
    axes = fig.subplots(3, len(panels), sharex=True, squeeze=False)
    for c, (label, t, R_gt, R_est) in enumerate(panels):
        _draw_euler(axes[:, c], t - t[0], R_est, R_gt, labels=c == 0)
        axes[0][c].set_title(label, fontsize="medium")
        axes[-1][c].set_xlabel("time [s]")
    axes[0][0].legend(loc="best", fontsize="x-small")
    fig.suptitle(title, fontsize="medium")
    fig.savefig(path, dpi=100, format="png")
