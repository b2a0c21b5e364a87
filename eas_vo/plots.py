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
from eas_vo.geometry.uncertainty import euler_sigmas_deg


def _figure(**kwargs):
    """A new figure on its own Agg canvas (PNG output whatever the process's backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


#: How a frame's status is drawn in the status row (ok and first: not at all), bottom to top.
STATUS_COLOURS = {"weak": "tab:orange", "lost": "tab:red"}
#: The widest a gallery shows an image [figure px]; the margin [px] around each for its labels.
GALLERY_MAX_PX, GALLERY_MARGIN_PX = 480, 24


def plot_rotation(path: str | Path, result, title: str = "") -> None:
    """rotation_figure, saved as PNG."""
    rotation_figure(result, title).savefig(path, dpi=110, format="png")


def rotation_figure(result, title: str = ""):
    """Estimated (aligned to ground truth at the first frame) and true roll/pitch/yaw over time,
    like the paper's Fig. 3, each estimated angle in a band of +-1 sigma (from the backend's
    covariance, `result.covariance`, else the chain's, `result.chain_covariance`; none when
    both are None), then the angular velocity per axis (edges against ground truth), over a
    tracking panel: the rotation error [deg] per frame (with ground truth) beside the error the
    covariance predicts (its RMS, sqrt(trace)), and loop closures marked at the frame that closed
    them; under it a thin status row, one line per status, marking the weak and lost frames.
    Without ground truth only the estimate is drawn. The title's second line gives the APE, the
    NC and the ground truth's time offset the errors were measured with, the angular-velocity
    RMS error and the RPE over 1 s (metrics, where present)."""
    t0 = result.t[0]
    errors = result.errors
    covariance = result.covariance if result.covariance is not None else result.chain_covariance
    # Fixed margins, not a layout engine: drawn once per run, a constrained layout (which draws
    # the figure twice) doubled a short run's time; the margins fit the longest labels drawn.
    fig = _figure(figsize=(8, 10))
    fig.subplots_adjust(left=0.1, right=0.97, top=0.925, bottom=0.05, hspace=0.14)
    axes = fig.subplots(6, 1, sharex=True, height_ratios=(1, 1, 1, 1, 0.8, 0.16))
    _draw_angular_velocity(axes[3], result, t0)
    axes = [*axes[:3], *axes[4:]]  # below: roll, pitch, yaw 0-2, the tracking panel 3, the status row 4
    if errors is not None and errors.valid.any():
        shown = errors.valid
        R_shown = errors.R_w_c_aligned  # aligned on the left (a world rotation): the covariance is unchanged
        _draw_euler(
            axes[:3], result.t[shown] - t0, R_shown, errors.R_w_c_gt, sigma_deg=_sigmas(R_shown, covariance, shown)
        )
        axes[3].plot(result.t[shown] - t0, np.degrees(errors.ape_rad), color="k", lw=0.9, label="error")
        if covariance is not None:
            predicted = np.degrees(np.sqrt(np.clip(np.trace(covariance[shown], axis1=1, axis2=2), 0, None)))
            _plot_within(axes[3], result.t[shown] - t0, predicted, np.degrees(errors.ape_rad), label="predicted (RMS)")
        axes[3].set_ylabel("error [deg]")
    else:
        shown = np.ones(len(result.t), bool)
        _draw_euler(axes[:3], result.t - t0, result.R_w_c, sigma_deg=_sigmas(result.R_w_c, covariance, shown))
        axes[3].set_yticks([])
        axes[3].set_ylabel("tracking")
    _status_row(axes[4], result.records, t0)
    for k, j in enumerate(sorted({e.j for e in result.edges if e.loop and 0 <= e.j < len(result.t)})):
        axes[3].axvline(result.t[j] - t0, color="tab:blue", lw=0.8, label="loop closed" if k == 0 else None)
    axes[0].legend(loc="best", fontsize="small")
    if axes[3].get_legend_handles_labels()[0]:
        axes[3].legend(loc="upper left", fontsize="small", ncol=4)
    axes[3].grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    m = result.metrics
    facts = []
    if "ape_mean_rad" in m:
        facts.append(f"average APE {m['ape_mean_rad']:.4f} rad, average NC {m['nc_mean']:.1f}")
    if "time_offset_s" in m and errors is not None:
        facts.append(
            f"ground truth time offset {m['time_offset_s'] * 1e3:+.1f} ms"
            + (" (estimated)" if m.get("time_offset_estimated") else "")
        )
    if facts:
        title += "\n" + ", ".join(facts)
    motion = []
    if m.get("omega_rms_deg_s") is not None:
        motion.append(f"angular velocity RMS error {m['omega_rms_deg_s']:.1f} deg/s")
    if m.get("rpe_1s_mean_deg") is not None:
        motion.append(f"RPE over 1 s {m['rpe_1s_mean_deg']:.2f} deg")
    if motion:
        title += "\n" + ", ".join(motion)
    fig.suptitle(title, fontsize="medium")
    return fig


def _draw_angular_velocity(ax, result, t0: float) -> None:
    """The angular velocity per camera axis [deg/s] the consecutive edges measured (dots) over
    the ground truth's over the same intervals (lines), evaluation.angular_velocities."""
    from eas_vo.evaluation.motion import angular_velocities

    errors = result.errors if result.errors is not None and result.errors.valid.any() else None
    mid, est, gt = angular_velocities(result.t, result.edges, errors)
    for k, (name, colour) in enumerate(zip("xyz", ("tab:red", "tab:green", "tab:blue"))):
        if gt is not None:
            ax.plot(mid - t0, np.degrees(gt[:, k]), color=colour, lw=0.9, label=f"omega {name} truth")
        ax.plot(mid - t0, np.degrees(est[:, k]), ".", color=colour, ms=2.5, label=f"omega {name} estimate")
    ax.set_ylabel("ang. velocity [deg/s]")
    ax.grid(alpha=0.3)
    if len(mid):
        ax.legend(loc="upper left", fontsize="x-small", ncol=3)


def _status_row(ax, records, t0: float) -> None:
    """Mark each run of consecutive weak (or lost) frames on its status's line of `ax`, from the
    previous frame's time to its own (the interval its measurement covers); the lines are
    labelled with the status and its frame count."""
    runs = {status: [] for status in STATUS_COLOURS}  # (start [s], width [s]) per status
    for status, run in itertools.groupby(zip(records, records[1:]), key=lambda pair: pair[1].status):
        run = list(run)
        if status in runs:
            start, end = run[0][0].t, run[-1][1].t  # from the frame before the run to its last
            runs[status].append((start - t0, end - start))
    counts = {status: sum(r.status == status for r in records) for status in STATUS_COLOURS}
    for row, (status, spans) in enumerate(runs.items()):
        if spans:
            ax.broken_barh(spans, (row + 0.1, 0.8), color=STATUS_COLOURS[status], lw=0)
    ax.set_ylim(0, len(runs))
    ax.set_yticks(np.arange(len(runs)) + 0.5, [f"{status} ({counts[status]})" for status in runs], fontsize="x-small")
    ax.tick_params(axis="y", length=0)
    ax.grid(axis="x", alpha=0.3)


def _sigmas(R_w_c: np.ndarray, covariance: np.ndarray | None, shown: np.ndarray) -> np.ndarray | None:
    """The 1-sigma [deg] (N, 3) of the roll, pitch and yaw of the shown frames' R_w_c, from the
    covariance of every frame (None without one)."""
    return None if covariance is None else euler_sigmas_deg(R_w_c, np.asarray(covariance)[shown])


#: How far [in spans of the curves' own range, at least BAND_MIN_DEG] a band may widen a
#: panel beyond its curves: a frame whose sigma is huge (a frame the graph ties loosely) fills
#: the panel rather than flattening every curve in it.
BAND_REACH, BAND_MIN_DEG = 0.5, 5.0


def _plot_within(ax, t: np.ndarray, values: np.ndarray, curves: np.ndarray, label: str) -> None:
    """A dashed grey line of `values` over `t`, the axis limited to what `curves` need (and the
    line within BAND_REACH of them), as the Euler bands are."""
    ax.plot(t, values, color="0.45", lw=0.9, ls="--", label=label)
    _limit(ax, curves, values, values)


def _limit(ax, curves: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """The y-axis of `ax` around the finite `curves` and, within BAND_REACH of them, the band lo..hi."""
    finite = curves[np.isfinite(curves)]
    if not len(finite):
        return
    bottom, top = float(finite.min()), float(finite.max())
    reach = BAND_REACH * max(top - bottom, BAND_MIN_DEG)
    band_lo, band_hi = np.nanmin(np.append(lo, bottom)), np.nanmax(np.append(hi, top))
    bottom, top = max(min(bottom, band_lo), bottom - reach), min(max(top, band_hi), top + reach)
    margin = 0.05 * max(top - bottom, 1e-6)
    ax.set_ylim(bottom - margin, top + margin)


def _draw_euler(
    column,
    t: np.ndarray,
    R_est: np.ndarray,
    R_gt: np.ndarray | None = None,
    labels: bool = True,
    sigma_deg: np.ndarray | None = None,
) -> None:
    """Roll, pitch, yaw [deg] over t [s] into three axes: the estimate over the ground truth (if
    any), with a band of +-sigma_deg (N, 3) about the estimate when given."""
    est = np.unwrap(euler_zyx_deg(R_est), period=360, axis=0)
    gt = None if R_gt is None else np.unwrap(euler_zyx_deg(R_gt), period=360, axis=0)
    for k, (ax, name) in enumerate(zip(column, ("roll", "pitch", "yaw"))):
        if gt is not None:
            ax.plot(t, gt[:, k], color="0.2", lw=1.4, label="ground truth")
        ax.plot(t, est[:, k], color="tab:red", lw=1.0, label="estimate")
        if sigma_deg is not None:
            lo, hi = est[:, k] - sigma_deg[:, k], est[:, k] + sigma_deg[:, k]
            ax.fill_between(t, lo, hi, color="tab:red", alpha=0.2, lw=0, label="estimate ± 1 sigma")
            _limit(ax, est[:, k] if gt is None else np.concatenate([est[:, k], gt[:, k]]), lo, hi)
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
    cell_w, cell_h = (
        (shown_px + GALLERY_MARGIN_PX) / 100,
        (shown_px * height / width + GALLERY_MARGIN_PX) / 100,
    )  # [in] at 100 dpi
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


#: The colours of frontends that have no fixed one (compare fixes the paper's six:
#: gallery.PAPER_COLOURS), taken in turn.
SPARE_COLOURS = ("tab:pink", "tab:gray", "tab:olive", "tab:cyan", "#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173")

#: How the sweep points of one frontend are told apart: a line style (ape_time) and a hatch (ape_bars) each.
SWEEP_STYLES = ("-", "--", ":", "-.")
SWEEP_HATCHES = ("", "//", "..", "xx", "\\\\", "++")


def frontend_colours(frontends, fixed: dict | None = None) -> dict[str, str]:
    """A colour per frontend: `fixed`'s where it has one, SPARE_COLOURS (cycled) for the others
    in the order given; give every figure of a grid the same mapping."""
    fixed = fixed or {}
    others = [f for f in dict.fromkeys(frontends) if f not in fixed]
    return {**fixed, **{f: SPARE_COLOURS[k % len(SPARE_COLOURS)] for k, f in enumerate(others)}}


def _method_title(method: str, equals: list[str]) -> str:
    """A method's name, and those whose results are its own."""
    return method + "".join(f"\n= {other}" for other in equals) + (" (same trajectories)" if equals else "")


def _panel_name(dataset: str) -> str:
    return Path(dataset.rstrip("/")).name or dataset


def plot_ape_bars(path: str | Path, rows: list[dict], equal: dict | None = None, colours: dict | None = None) -> None:
    """ape_bars_figure, saved as PNG."""
    ape_bars_figure(rows, equal, colours).savefig(path, dpi=110, format="png")


def ape_bars_figure(rows: list[dict], equal: dict | None = None, colours: dict | None = None):
    """Average APE [rad] (top) and average NC (bottom) of each finished cell, a column of panels
    per dataset: a group of bars per method (tracker+backend), named with the methods
    `equal[(dataset, method)]` whose results are its own; a bar per source coloured by frontend
    (frontend_colours), hatched per sweep point, its value on it ("failed" on a failed cell's
    empty bar). `rows` as compare's table."""
    equal = equal or {}
    colours = colours or frontend_colours(r["frontend"] for r in rows)
    datasets = list(dict.fromkeys(r["dataset"] for r in rows))
    sources = list(dict.fromkeys((r["frontend"], r["sweep"]) for r in rows))
    sweeps = list(dict.fromkeys(r["sweep"] for r in rows))
    by_key = {(r["dataset"], r["method"], r["frontend"], r["sweep"]): r for r in rows}
    columns = {d: list(dict.fromkeys(r["method"] for r in rows if r["dataset"] == d)) for d in datasets}
    most = max(len(c) for c in columns.values())
    panel_width = max(4.0, 0.42 * len(sources) * most + 1.6)
    fig = _figure(figsize=(panel_width * len(datasets), 6.4), layout="constrained")
    axes = fig.subplots(2, len(datasets), squeeze=False, sharex="col")
    width = 0.8 / len(sources)
    for c, dataset in enumerate(datasets):
        methods = columns[dataset]
        for ax, key, what, fmt in (
            (axes[0][c], "ape_mean_rad", "average APE [rad]", "{:.3f}"),
            (axes[1][c], "nc_mean", "average NC", "{:.0f}"),
        ):
            for s, (frontend, sweep) in enumerate(sources):
                cells = [by_key.get((dataset, m, frontend, sweep)) for m in methods]
                values = np.array(
                    [
                        np.nan if r is None else 0.0 if r["status"] != "ok" else np.nan if r[key] is None else r[key]
                        for r in cells
                    ],
                    dtype=float,
                )
                texts = [
                    "failed" if r is not None and r["status"] != "ok" else "" if v != v else fmt.format(v)
                    for r, v in zip(cells, values)
                ]
                bars = ax.bar(
                    np.arange(len(methods)) + (s - (len(sources) - 1) / 2) * width,
                    values,
                    width,
                    color=colours[frontend],
                    hatch=SWEEP_HATCHES[sweeps.index(sweep) % len(SWEEP_HATCHES)],
                    edgecolor="white",
                    linewidth=0.5,
                    label=" ".join(filter(None, [frontend, sweep])),
                )
                ax.bar_label(
                    bars,
                    labels=texts,
                    fontsize="x-small",
                    rotation=90 if len(sources) * len(methods) > 8 else 0,
                    padding=2,
                )
            ax.set_ylabel(what)
            ax.margins(y=0.18)
            ax.grid(axis="y", alpha=0.3)
        axes[0][c].set_title(_panel_name(dataset), fontsize="medium")
        axes[1][c].set_xticks(
            np.arange(len(methods)), [_method_title(m, equal.get((dataset, m), [])) for m in methods], fontsize="small"
        )
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right upper", fontsize="small", title="source")
    return fig


def plot_ape_time(path: str | Path, series: dict, equal: dict | None = None, colours: dict | None = None) -> None:
    """ape_time_figure, saved as PNG."""
    ape_time_figure(series, equal, colours).savefig(path, dpi=110, format="png")


def ape_time_figure(series: dict, equal: dict | None = None, colours: dict | None = None):
    """APE [rad] over time [s]: {(dataset, method, frontend, sweep label): (t, ape)}, a row of
    panels per dataset and in it a panel per method (its title also naming the methods
    `equal[(dataset, method)]` whose trajectories are its own), a line per source coloured by
    frontend (frontend_colours), styled per sweep point; one shared APE axis."""
    colours = colours or frontend_colours(f for _, _, f, _ in series)
    equal = equal or {}
    datasets = list(dict.fromkeys(d for d, _, _, _ in series))
    panels = {d: list(dict.fromkeys(m for d2, m, _, _ in series if d2 == d)) for d in datasets}
    sweeps = list(dict.fromkeys(s for _, _, _, s in series))
    ncols = max(len(p) for p in panels.values())
    fig = _figure(figsize=(1.2 + 4.2 * ncols, 0.6 + 2.9 * len(datasets)), layout="constrained")
    axes = fig.subplots(len(datasets), ncols, squeeze=False, sharey=True)
    for r, dataset in enumerate(datasets):
        for c in range(ncols):
            ax = axes[r][c]
            if c >= len(panels[dataset]):
                ax.set_axis_off()
                continue
            method = panels[dataset][c]
            for (d, m, frontend, sweep), (t, ape) in series.items():
                if (d, m) == (dataset, method):
                    ax.plot(
                        t,
                        ape,
                        lw=1.0,
                        color=colours[frontend],
                        ls=SWEEP_STYLES[sweeps.index(sweep) % len(SWEEP_STYLES)],
                        label=" ".join(filter(None, [frontend, sweep])),
                    )
            name = _panel_name(dataset) + ": " if len(datasets) > 1 else ""
            ax.set_title(name + _method_title(method, equal.get((dataset, method), [])), fontsize="medium")
            ax.grid(alpha=0.3)
            ax.set_xlabel("time [s]")
            if c == 0:
                ax.set_ylabel("APE [rad]")
    labels = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            labels.setdefault(label, handle)
    fig.legend(list(labels.values()), list(labels), loc="outside right upper", fontsize="small", title="source")
    if len(datasets) == 1:
        fig.suptitle(_panel_name(datasets[0]), fontsize="medium")
    return fig


def plot_protocol_errors(path: str | Path, scores: dict, title: str = "") -> None:
    """The rotation protocol's errors over time, one line per method: {label: ProtocolScore
    (evaluation.rotation_protocol)}; the absolute error [deg] on a log axis (a gyro's drift and
    a tracker's degrees on one figure), the 1 s relative error [deg/s] below it."""
    fig = _figure(figsize=(11, 7.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for label, s in scores.items():
        rms = s.summary()["absolute_rms_deg"]
        (line,) = top.plot(s.t, np.maximum(s.error_deg, 1e-2), lw=1.0, label=f"{label} (RMS {rms:.2f} deg)")
        bottom.plot(s.relative_t, s.relative_deg_s, lw=1.0, color=line.get_color())
    top.set_yscale("log")
    top.set_ylabel("absolute error [deg]")
    bottom.set_ylabel("error over the next 1 s [deg/s]")
    bottom.set_xlabel("time from the sequence's start [s]")
    for ax in (top, bottom):
        ax.grid(alpha=0.3, which="both")
    fig.legend(*top.get_legend_handles_labels(), loc="outside lower center", fontsize="small", ncols=3)
    fig.suptitle(title, fontsize="medium")
    fig.savefig(path, dpi=110, format="png")


#: The value axis of a sweep over a known key: (what the value is, its unit) for the label
#: and the title; another key is named as it was swept.
SWEEP_AXES = {
    "dataset.illumination": ("illumination", "x the scene's own light"),
    "dataset.speed": ("camera speed", "x the path's own; synthetic:default 44 deg/s mean"),
    "dataset.translation_scale": ("camera translation", "x the path's own"),
}


def plot_sweep(path: str | Path, key: str, curves: dict, colours: dict | None = None) -> None:
    """sweep_figure, saved as PNG."""
    sweep_figure(key, curves, colours).savefig(path, dpi=110, format="png")


def sweep_figure(key: str, curves: dict, colours: dict | None = None):
    """Average APE and NC against a swept value: {(dataset, method, frontend): (n, 3) array of
    (value, NC, APE)}, a line per frontend coloured by it (frontend_colours), styled per method
    and labelled with the method and dataset when there are several; the value axis labelled
    with its unit (SWEEP_AXES), logarithmic when the values span 4x or more (base 2 when they
    are powers of 2 of the smallest), ticked at the swept values; a title naming the dataset
    and the method when there is one."""
    from matplotlib.ticker import FuncFormatter

    colours = colours or frontend_colours(f for _, _, f in curves)
    methods = list(dict.fromkeys(m for _, m, _ in curves))
    datasets = list(dict.fromkeys(d for d, _, _ in curves))
    fig = _figure(figsize=(13, 4.4), layout="constrained")
    ape_ax, nc_ax = fig.subplots(1, 2)
    several = {"dataset": len(datasets) > 1, "method": len(methods) > 1}
    for (dataset, method, frontend), xy in curves.items():
        label = " ".join(
            [frontend]
            + ([method] if several["method"] else [])
            + ([_panel_name(dataset)] if several["dataset"] else [])
        )
        style = {
            "color": colours[frontend],
            "ls": SWEEP_STYLES[methods.index(method) % len(SWEEP_STYLES)],
            "lw": 1.2,
            "ms": 4,
        }
        ape_ax.plot(xy[:, 0], xy[:, 2], "o", label=label, **style)
        nc_ax.plot(xy[:, 0], xy[:, 1], "o", label=label, **style)
    values = np.unique(np.concatenate([xy[:, 0] for xy in curves.values()])) if curves else np.array([1.0])
    what, unit = SWEEP_AXES.get(key, (key, ""))
    for ax, figure in ((ape_ax, "average APE [rad]"), (nc_ax, "average NC (corners tracked per frame)")):
        _sweep_axis(ax, values)
        ax.set_xlabel(f"{what} [{unit}]" if unit else what)
        ax.set_ylabel(figure)
        ax.grid(alpha=0.3, which="major")
    ape_ax.set_yscale("log")
    ape_ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # 0.1, not 10^-1
    ape_ax.yaxis.set_minor_formatter(  # and 0.2, 0.5 between
        FuncFormatter(lambda v, _: f"{v:g}" if round(v / 10 ** np.floor(np.log10(v))) in (2, 5) else "")
    )
    fig.legend(*ape_ax.get_legend_handles_labels(), loc="outside right upper", fontsize="small", title="source")
    title = f"Average APE and NC against {what}"
    named = [_panel_name(datasets[0])] if len(datasets) == 1 else []
    named += [methods[0]] if len(methods) == 1 else []
    fig.suptitle(title + (f": {', '.join(named)}" if named else ""), fontsize="medium")
    return fig


def _sweep_axis(ax, values: np.ndarray) -> None:
    """A sweep's value axis: logarithmic where the values are positive and span 4x or more
    (base 2 where each is a power of 2 of the smallest, else base 10), ticked and labelled at
    the values themselves (up to 12 of them)."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    if values.min() > 0 and values.max() >= 4 * values.min():
        octaves = np.log2(values / values.min())
        ax.set_xscale("log", base=2 if np.allclose(octaves, np.round(octaves)) else 10)
    if len(values) <= 12:
        ax.xaxis.set_major_locator(FixedLocator(values))
        ax.xaxis.set_minor_locator(NullLocator())
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def plot_euler_grid(
    path: str | Path, panels: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], title: str = ""
) -> None:
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


def plot_keyframes(path: str | Path, panels: list[tuple], title: str = "") -> None:
    """The paper's Fig. 4 for one sequence: a column per source, rows x, y, z [m] of the
    Sim(3)-aligned keyframe positions (red dots) over the ground truth (black line), and each
    keyframe's translation APE [m] at the bottom. `panels`: (label, keyframe t [s] (M,),
    aligned positions (M, 3) [m], ground truth PoseSeries)."""
    fig = _figure(figsize=(3.0 * len(panels) + 0.8, 7.5), layout="constrained")
    axes = fig.subplots(4, len(panels), sharex="col", squeeze=False)
    for c, (label, t, p, gt) in enumerate(panels):
        t0 = gt.t[0]
        shown = (gt.t >= t[0] - 0.5) & (gt.t <= t[-1] + 0.5)
        at = np.array([np.argmin(np.abs(gt.t - v)) for v in t])
        for axis, name in enumerate("xyz"):
            ax = axes[axis][c]
            ax.plot(gt.t[shown] - t0, gt.p_w_c[shown, axis], "k-", lw=1, label="ground truth")
            ax.plot(t - t0, p[:, axis], "r.", ms=4, label="keyframes")
            if c == 0:
                ax.set_ylabel(f"{name} [m]")
        ax = axes[3][c]
        ax.plot(t - t0, np.linalg.norm(p - gt.p_w_c[at], axis=1), "r.-", ms=4, lw=0.8)
        if c == 0:
            ax.set_ylabel("APE [m]")
        ax.set_xlabel("time [s]")
        axes[0][c].set_title(label, fontsize="medium")
    axes[0][0].legend(loc="best", fontsize="x-small")
    fig.suptitle(title, fontsize="medium")
    fig.savefig(path, dpi=100, format="png")
