"""Checks every measured rotation's covariance against ground truth: the NEES (docs/uncertainty.md).

For every edge R_i_j a run measures (consecutive, keyframe with tracker.klt.keyframe_interval=3,
loop), tagged by its kind and its two-view model, the error against the ground truth's relative
rotation between the two frame times (in frame j; the run's ground-truth time offset:
status_calibration.ground_truth) is delta = Log(R_est^T R_gt) [rad], so that R_gt = R_est Exp(delta),
the covariance's convention (geometry.covariance), and its NEES delta^T Sigma^-1 delta. With a
right covariance the NEES is chi-square with 3 degrees of freedom: mean 3, median 2.366, above
11.345 for 1 % of the edges.

Data as benchmarks/status_calibration.py: choice data `synthetic:default` and the real excerpt's
first 20 s, report data simulator seeds 41-43 and the real excerpt's 20-30 s; klt with
configs/paper.toml (five-point) and configs/best.toml (rotation-only, loops by homography), each
with the backend `chain` (the edges do not depend on it) on every frontend, and the `match`
tracker (its defaults) on one frontend per data; each with both covariance methods. The `cmax`
tracker (events only, its defaults; its covariance is its own, from the contrast objective's
curvature: method `curvature`, model `cmax`) on the simulated data and on the real excerpt's
first 0.5 s, the only part with events (`real 0-0.5 s`, within the choice data's time).

The factors and the method are chosen on the FITTED run set only (klt on the frontends of
status_calibration, `match` on MATCH_FRONTEND): the other runs (klt on the simulator's
`original`, `slice` and `sits`, cmax) are report-only, on the choice data too, so that adding
them changes no factor. On the fitted choice runs, per method, one scale factor per model family
(`essential`; `rotation`, which takes the homography's too) is fitted: the factor k (covariance
times k) that brings the choice data's median NEES to chi-square(3)'s median (SCALE_RULE). The
method is chosen by METHOD_RULE. The tables: per run; per split and method with and without the
factors, over the fitted runs and over every run; the report-only runs per source.

    python benchmarks/nees.py [--rows FILE] [--from FILE ...] [--only LABEL ...] [--methods M ...]

--rows writes every edge (one CSV line each); --from reads such files instead of running.
A run's NEES is taken with the covariance as the code gave it, then divided back by the
factor the code applied (geometry.covariance.SCALE at run time, in the rows): the tables
always start from the unscaled covariance.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from status_calibration import REAL_FRONTENDS, REAL_OFFSET_S, SYNTHETIC_FRONTENDS, columns, ground_truth
from study import add_real, real_folder

from eas_vo import concurrency, config, pipeline
from eas_vo.geometry import covariance as cov_module
from eas_vo.geometry.rotations import matrix_to_rotvec
from eas_vo.trackers import measurement
from eas_vo.types import PoseSeries

#: chi-square(3): its 99 % bound and its median.
CHI2_P99 = 11.345
CHI2_MEDIAN = 2.366
#: The factor rule, fixed before looking at the data: per method and model family, k = (median
#: NEES of the choice data's edges of that family, all runs pooled) / CHI2_MEDIAN; kept where it
#: lies outside [1 / KEEP_WITHIN, KEEP_WITHIN], else 1 (a covariance within 25 % of right).
KEEP_WITHIN = 1.25
SCALE_RULE = "median NEES of the choice data = chi-square(3)'s median 2.366, per model family"
#: The method rule, fixed before looking: each method with its own factors (SCALE_RULE); on the
#: choice data, the mean over the runs of |ln(mean NEES / 3)|, the lower wins; within 0.05 of
#: each other, the lower mean fraction above CHI2_P99.
METHOD_RULE = "after its own factors, the choice runs' mean |ln(mean NEES / 3)|; within 0.05, the smaller tail"
#: The `match` tracker runs on one frontend per data.
MATCH_FRONTEND = {
    "synthetic": "histeq",
    "real": "histeq",
}  # on the dim simulated eas images ORB matches one frame in 200
FAMILY = {"essential": "essential", "rotation": "rotation", "homography": "rotation"}
#: klt's report-only frontends on the simulated data (not in the fitted run set).
EXTRA_SYNTHETIC_FRONTENDS = ("original", "slice", "sits")
#: cmax reads no images (the `no_image` frontend whatever run.frontend says); its covariance is
#: its own (each window's Hessian of the contrast), without a method to choose or a factor.
CMAX_METHOD = "curvature"
#: The real excerpt has events for its first 0.5 s only: cmax runs there (label, split, start
#: [s], duration [s]); the time lies within the choice data's 0-20 s, though cmax fits nothing.
REAL_EVENTS = ("real 0-0.5 s", "choice", 0.0, 0.5)
#: The upper triangle of a 3x3 matrix, row by row, as the rows store it.
UPPER = ("xx", "xy", "xz", "yy", "yz", "zz")
_IU = np.triu_indices(3)
FIELDS = (
    "data",
    "split",
    "tracker",
    "config",
    "frontend",
    "method",
    "kind",
    "model",
    "i",
    "j",
    "inliers",
    "inlier_ratio",
    "residual_px",
    "focal_px",
    "gt_angle_deg",
    "gt_baseline_m",
    "error_deg",
    "sigma_px",
    "nees",
    "scale",
    *(f"delta_{a}" for a in "xyz"),  # [rad]
    *(f"cov_{a}" for a in UPPER),  # the covariance as the run's code gave it [rad^2]
    *(f"ref_{a}" for a in UPPER),  # the reference's own noise (reference_covariance) [rad^2]
)


def tagging() -> dict:
    """{covariance bytes: model}, filled by every two-view measurement from now on: the edges a
    tracker returns carry the measurement's covariance array as it was made."""
    models = {}
    measure = measurement.rotation_from_correspondences

    def tagged(*args, **kwargs):
        found = measure(*args, **kwargs)
        if found is not None:
            models[np.asarray(found.covariance).tobytes()] = found.model
        return found

    measurement.rotation_from_correspondences = tagged
    return models


def fitted(data: str, tracker: str, frontend: str) -> bool:
    """Whether a run belongs to the run set the factors and the method are chosen on (klt on
    status_calibration's frontends, `match` on MATCH_FRONTEND); the others are report-only."""
    real = data.startswith("real")
    if tracker == "klt":
        return frontend in (REAL_FRONTENDS if real else SYNTHETIC_FRONTENDS)
    if tracker == "match":
        return frontend == MATCH_FRONTEND["real" if real else "synthetic"]
    return False


def runs(real: str, seeds: list[int], only: list[str] | None) -> list[tuple]:
    """(label, split, dataset, tracker, config file, frontend, run settings) for every run: the
    fitted ones first for each data, then the report-only ones."""
    found = []
    seeds = [n for n in seeds if not only or f"seed {n}" in only]  # simulated (once) only where needed
    for label, (split, dataset, frontends, extra) in columns(real, seeds).items():
        if only and label not in only:
            continue
        kind = "real" if label.startswith("real") else "synthetic"
        for file, frontend in itertools.product(("paper", "best"), frontends):
            found.append((label, split, dataset, "klt", file, frontend, extra))
        found.append((label, split, dataset, "match", "paper", MATCH_FRONTEND[kind], extra))
        if kind == "synthetic":
            for file, frontend in itertools.product(("paper", "best"), EXTRA_SYNTHETIC_FRONTENDS):
                found.append((label, split, dataset, "klt", file, frontend, extra))
            found.append((label, split, dataset, "cmax", "paper", "no_image", extra))
    label, split, start, duration = REAL_EVENTS
    if real and Path(real).is_dir() and (not only or label in only):
        extra = {"start_s": start, "duration_s": duration, "time_offset_s": REAL_OFFSET_S}
        found.append((label, split, real, "cmax", "paper", "no_image", extra))
    return found


def methods_of(tracker: str, methods: list[str]) -> list[str]:
    """The covariance methods a tracker runs with: cmax has its own only."""
    return [CMAX_METHOD] if tracker == "cmax" else methods


def reference_sigma_rad(poses: PoseSeries, t0: float, t1: float) -> np.ndarray:
    """The per-axis noise [rad] (3,) of one ground-truth orientation sample in its own frame,
    from the samples within [t0, t1] [s]: each sample against the midpoint (slerp) of its
    neighbours k samples away leaves 1.5 sigma^2 of white noise plus the motion's curvature,
    which grows as k^4; k = 1 and 2 (robust variances, from the median absolute deviation)
    separate the two. About 0 for the simulator (exact)."""
    keep = (poses.t >= t0) & (poses.t <= t1)
    R = Rotation.from_quat(poses.q_w_c[keep])
    if len(R) < 5:
        return np.zeros(3)

    def variance(k: int) -> np.ndarray:
        a, b, c = R[: len(R) - 2 * k], R[2 * k :], R[k : len(R) - k]
        residual = ((a * Rotation.from_rotvec(0.5 * (a.inv() * b).as_rotvec())).inv() * c).as_rotvec()
        return (1.4826 * np.median(np.abs(residual - np.median(residual, axis=0)), axis=0)) ** 2

    v1, v2 = variance(1), variance(2)
    curvature = np.maximum(v2 - v1, 0.0) / 15.0
    return np.sqrt(np.maximum(v1 - curvature, 0.0) / 1.5)


def reference_covariance(gt, sigma_rad: np.ndarray, i: int, j: int, R_gt_ij: np.ndarray) -> np.ndarray:
    """The covariance [rad^2] (3, 3) the reference's own noise adds to R_gt_ij (right
    perturbation in frame j): each end interpolated (slerp) between two samples with weights
    w and 1 - w carries (w^2 + (1 - w)^2) of a sample's variance; the two ends are taken as
    independent (frames lie several samples apart)."""
    D = np.diag(sigma_rad**2)
    t = gt.poses.t
    share = []
    for time in (gt.times[i], gt.times[j]):
        k = int(np.clip(np.searchsorted(t, time), 1, len(t) - 1))
        w = (time - t[k - 1]) / max(t[k] - t[k - 1], 1e-12)
        share.append(w**2 + (1 - w) ** 2)
    return share[0] * R_gt_ij.T @ D @ R_gt_ij + share[1] * D


def edge_rows(models: dict, label, split, dataset, tracker, file, frontend, extra, method) -> list[dict]:
    """One row per edge of the run with ground truth at both ends."""
    assignments = [f"tracker.covariance={method}"] if method in cov_module.METHODS else []
    if tracker == "klt":
        assignments.append("tracker.klt.keyframe_interval=3")
    cfg = config.resolve(
        file, {"dataset": dataset, "frontend": frontend, "tracker": tracker, "backend": "chain", **extra}, assignments
    )
    result = pipeline.run(cfg)
    gt = ground_truth(cfg, result)
    sigma_ref = reference_sigma_rad(gt.poses, gt.times[0], gt.times[-1])
    rows = []
    for e in result.edges:
        R_i, R_j = gt.R_w_c[e.i], gt.R_w_c[e.j]
        if not (np.isfinite(R_i[0, 0]) and np.isfinite(R_j[0, 0])):
            continue
        R_gt = R_i.T @ R_j
        delta = matrix_to_rotvec(e.R_i_j.T @ R_gt)
        sigma = e.noise_covariance()
        untagged = "cmax" if tracker == "cmax" else "other"  # cmax's edges are not two-view measurements
        model = models.get(np.asarray(e.covariance).tobytes(), untagged) if e.covariance is not None else "quality"
        with np.errstate(all="ignore"):
            value = float(delta @ np.linalg.solve(sigma, delta)) if np.all(np.isfinite(sigma)) else math.nan
        rows.append(
            {
                "data": label,
                "split": split,
                "tracker": tracker,
                "config": file,
                "frontend": frontend,
                "method": method,
                "kind": "loop" if e.loop else "consecutive" if e.j == e.i + 1 else "keyframe",
                "model": model,
                "i": e.i,
                "j": e.j,
                "inliers": e.inliers,
                "inlier_ratio": e.inlier_ratio,
                "residual_px": e.residual_rad * gt.focal_px,
                "focal_px": gt.focal_px,
                "gt_angle_deg": math.degrees(np.linalg.norm(matrix_to_rotvec(R_gt))),
                "gt_baseline_m": float(np.linalg.norm(gt.p_w_c[e.j] - gt.p_w_c[e.i])),
                "error_deg": math.degrees(np.linalg.norm(delta)),
                "sigma_px": e.sigma_rad * gt.focal_px,
                "nees": value,
                "scale": scale_of(method, model),
                **dict(zip(FIELDS[20:23], delta)),
                **dict(zip(FIELDS[23:29], sigma[_IU])),
                **dict(zip(FIELDS[29:35], reference_covariance(gt, sigma_ref, e.i, e.j, R_gt)[_IU])),
            }
        )
    return rows


def scale_of(method: str, model: str) -> float:
    """The factor geometry.covariance applies to this method's and model's covariance (1 where none)."""
    return float(getattr(cov_module, "SCALE", {}).get((method, FAMILY.get(model, "")), 1.0))


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for key in ("i", "j", "inliers"):
            row[key] = int(row[key])
        for key in FIELDS[10:]:
            row[key] = float(row[key])
    return rows


def symmetric(upper: np.ndarray) -> np.ndarray:
    """(N, 6) upper triangles (UPPER) -> (N, 3, 3) symmetric matrices."""
    M = np.zeros((len(upper), 3, 3))
    M[:, _IU[0], _IU[1]] = upper
    M[:, _IU[1], _IU[0]] = upper
    return M


class Edges:
    """The rows as arrays; the covariance unscaled (divided by the factor the run's code applied)."""

    def __init__(self, rows: list[dict]):
        rows = [r for r in rows if np.isfinite(r["nees"])]
        self.rows = rows
        for key in ("data", "split", "tracker", "config", "frontend", "method", "kind", "model"):
            setattr(self, key, np.array([r[key] for r in rows]))
        self.family = np.array([FAMILY.get(m, "other") for m in self.model])
        for key in ("gt_angle_deg", "gt_baseline_m", "error_deg", "sigma_px", "inliers", "inlier_ratio", "scale"):
            setattr(self, key, np.array([r[key] for r in rows], float))
        self.delta = np.array([[r[f"delta_{a}"] for a in "xyz"] for r in rows]).reshape(-1, 3)
        self.cov = symmetric(np.array([[r[f"cov_{a}"] for a in UPPER] for r in rows]).reshape(-1, 6))
        self.cov /= self.scale[:, None, None]
        self.ref = symmetric(np.array([[r[f"ref_{a}"] for a in UPPER] for r in rows]).reshape(-1, 6))
        self.focal_px = np.array([r["focal_px"] for r in rows], float)
        self.error_px = np.radians(self.error_deg) * self.focal_px
        self.sigma_px /= np.sqrt(self.scale)
        self.run = np.array(
            [f"{r['data']}|{r['tracker']}|{r['config']}|{r['frontend']}|{r['method']}" for r in rows], dtype=object
        )
        self.fitted = np.array([fitted(r["data"], r["tracker"], r["frontend"]) for r in rows], bool)

    def nees(self, factors: dict | None = None, reference: bool = False, use: np.ndarray | None = None) -> np.ndarray:
        """The NEES with the covariance of each (method, family) times its factor (none: 1), and
        with the reference's own noise added (`reference`)."""
        factors = factors or {}
        use = np.ones(len(self.rows), bool) if use is None else use
        k = np.array([factors.get((m, f), 1.0) for m, f in zip(self.method[use], self.family[use])])
        total = k[:, None, None] * self.cov[use] + (self.ref[use] if reference else 0.0)
        d = self.delta[use]
        return np.einsum("ni,ni->n", d, np.linalg.solve(total, d[..., None])[..., 0])


def misses(edges: Edges) -> None:
    """The NEES with an error the inliers' spread cannot show added to the code's covariance
    (its factors, `information`, the fitted runs, the reference's noise): a floor in pan and
    tilt [px of focal length], or a sigma on every axis proportional to the step's turn (the
    ground truth's, standing in for the measured one); the covariance times one multiplier `a`
    refitted so that the choice data's median NEES stays CHI2_MEDIAN (docs/uncertainty.md,
    "What the covariance misses")."""
    use = edges.fitted & (edges.method == "information") & (edges.family != "other")
    code = edges.cov[use] * edges.scale[use][:, None, None]
    d, choice = edges.delta[use], edges.split[use] == "choice"
    real = np.char.startswith(edges.data[use].astype(str), "real")
    pan_tilt = np.diag([1.0, 1.0, 0.0]) / edges.focal_px[use][:, None, None] ** 2
    turn = np.radians(edges.gt_angle_deg[use])[:, None, None] ** 2 * np.eye(3)
    terms = {"nothing": 0.0}
    terms.update({f"a floor in pan and tilt, {f:g} px": f**2 * pan_tilt for f in (0.5, 1.0)})
    terms.update({f"{100 * k:g} % of the turn, every axis": k**2 * turn for k in (0.01, 0.02, 0.03, 0.05)})
    print("\n## What the covariance misses\n")
    print("| added to the covariance | a | choice | report | report, simulated | report, real |")
    print("|---|---|---|---|---|---|")
    for name, extra in terms.items():

        def nees(a: float) -> np.ndarray:
            total = a * code + extra + edges.ref[use]
            return np.einsum("ni,ni->n", d, np.linalg.solve(total, d[..., None])[..., 0])

        lo, hi = -10.0, 10.0  # ln a
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.median(nees(math.exp(mid))[choice]) > CHI2_MEDIAN else (lo, mid)
        value = nees(math.exp(lo))
        cells = [
            f"{np.mean(value[m]):.2f} / {np.median(value[m]):.2f} / {np.mean(value[m] > CHI2_P99):.1%}"
            for m in (choice, ~choice, ~choice & ~real, ~choice & real)
        ]
        print(f"| {name} | {math.exp(lo):.2f} | " + " | ".join(cells) + " |")


def fit(edges: Edges, reference: bool) -> dict:
    """{(method, family): k} by SCALE_RULE on the fitted runs' choice data (bisection: each NEES
    falls as k grows)."""
    factors = {}
    for method, family in itertools.product(np.unique(edges.method[edges.fitted]), ("essential", "rotation")):
        use = edges.fitted & (edges.split == "choice") & (edges.method == method) & (edges.family == family)
        if use.sum() < 10:
            continue
        lo, hi = -10.0, 20.0  # ln k
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            above = np.median(edges.nees({(method, family): math.exp(mid)}, reference, use)) > CHI2_MEDIAN
            lo, hi = (mid, hi) if above else (lo, mid)
        k = math.exp(0.5 * (lo + hi))
        factors[(method, family)] = k if not (1 / KEEP_WITHIN <= k <= KEEP_WITHIN) else 1.0
    return factors


def summary(values: np.ndarray) -> str:
    if not len(values):
        return "- | - | - | 0"
    return f"{np.mean(values):.3g} | {np.median(values):.3g} | {np.mean(values > CHI2_P99):.1%} | {len(values)}"


def run_scores(edges: Edges, nees: np.ndarray, use: np.ndarray) -> tuple[float, float, float]:
    """Over the runs in `use`: mean |ln(mean NEES / 3)|, mean tail fraction, and the share of
    runs whose mean NEES lies in [1.5, 6] and tail is at most 5 %."""
    logs, tails, good = [], [], []
    for u in np.unique(edges.run[use]):
        m = use & (edges.run == u)
        mean, tail = float(np.mean(nees[m])), float(np.mean(nees[m] > CHI2_P99))
        logs.append(abs(math.log(mean / 3.0)))
        tails.append(tail)
        good.append(1.5 <= mean <= 6.0 and tail <= 0.05)
    return float(np.mean(logs)), float(np.mean(tails)), float(np.mean(good))


def choose_method(edges: Edges, factors: dict, reference: bool) -> str:
    """METHOD_RULE, on the fitted runs."""
    nees = edges.nees(factors, reference)
    scores = {}
    for method in np.unique(edges.method[edges.fitted]):
        use = edges.fitted & (edges.split == "choice") & (edges.method == method)
        log, tail, _ = run_scores(edges, nees, use)
        scores[method] = (log, tail)
        print(f"  {method}: choice runs' mean |ln(mean NEES / 3)| {log:.3f}, mean tail {tail:.1%}")
    ranked = sorted(scores, key=lambda m: scores[m][0])
    if len(ranked) > 1 and scores[ranked[1]][0] - scores[ranked[0]][0] <= 0.05:
        ranked = sorted(ranked[:2], key=lambda m: scores[m][1]) + ranked[2:]
    return ranked[0]


def report(edges: Edges, exact: dict, adopted: dict) -> None:
    """The tables: `exact` the factors fitted with the reference taken as exact, `adopted` those
    fitted with its noise added (the ones the code applies)."""
    variants = {
        "no factor": edges.nees(),
        "factor (exact reference)": edges.nees(exact),
        "factor, reference noise added": edges.nees(adopted, reference=True),
        "the code's factors (SCALE), reference noise added": edges.nees(
            dict(getattr(cov_module, "SCALE", {})), reference=True
        ),
    }
    print("\n## Per run (mean | median | above 11.345 | edges)\n")
    print(f"| data | tracker | config | frontend | method | fitted | {' | '.join(variants)} |")
    print("|---" * (6 + len(variants)) + "|")
    for u in dict.fromkeys(edges.run):
        m = edges.run == u
        fit = "yes" if edges.fitted[m][0] else "report only"
        print(f"| {' | '.join(u.split('|'))} | {fit} | {' | '.join(summary(v[m]) for v in variants.values())} |")
    print(
        "\n## By split (edges pooled; runs: mean |ln(mean/3)|, mean tail, share of runs on target); runs: `fitted`"
        " the run set the factors were chosen on, `every` every tracker and frontend (cmax, whose covariance has"
        " no method, with each method)\n"
    )
    print(
        "| runs | split | data | method | NEES | mean | median | above 11.345 | edges | runs: log ratio | runs: tail"
        " | runs on target |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    variants["no factor, reference noise added"] = edges.nees(reference=True)
    applied = variants["the code's factors (SCALE), reference noise added"]
    real = np.char.startswith(edges.data.astype(str), "real")
    own = ~np.isin(edges.method, cov_module.METHODS)  # a tracker's own covariance (cmax), no method to choose
    for runs_, split, kind, method in itertools.product(
        ("fitted", "every"), ("choice", "held-out"), ("all", "synthetic", "real"), np.unique(edges.method)
    ):
        if runs_ == "fitted":
            use = edges.fitted & (edges.method == method)
        elif method in cov_module.METHODS:
            use = (edges.method == method) | own
        else:
            continue
        use = use & (edges.split == split) & ((real == (kind == "real")) if kind != "all" else True)
        if not use.any():
            continue
        for name, values in variants.items():
            log, tail, good = run_scores(edges, values, use)
            print(
                f"| {runs_} | {split} | {kind} | {method} | {name} | {summary(values[use])} | {log:.2f} | {tail:.1%}"
                f" | {good:.0%} |"
            )
    scaled = variants["factor, reference noise added"]
    print(
        "\n## Report-only runs per source (seeds pooled), reference noise added, with the factors fitted here and"
        " with the code's (SCALE); cmax: no factor\n"
    )
    print(
        "| split | data | tracker | config | frontend | method | fitted factors: mean | median | above 11.345 | edges"
        " | the code's factors: mean | median | above 11.345 | edges |"
    )
    print("|---" * 14 + "|")
    extra = ~edges.fitted
    source = np.array(
        [
            f"{s}|{'real' if r else 'synthetic'}|{t}|{c}|{f}|{m}"
            for s, r, t, c, f, m in zip(edges.split, real, edges.tracker, edges.config, edges.frontend, edges.method)
        ],
        dtype=object,
    )
    for u in sorted(set(source[extra]), key=lambda u: (u.split("|")[0] != "held-out", u)):
        m = extra & (source == u)
        print(f"| {' | '.join(u.split('|'))} | {summary(scaled[m])} | {summary(applied[m])} |")
    print("\n## By kind and model, factor and reference noise (report data, fitted runs; cmax: every run)\n")
    print("| method | tracker | kind | model | mean | median | above 11.345 | edges |")
    print("|---|---|---|---|---|---|---|---|")
    held = (edges.split == "held-out") & (edges.fitted | own)
    for method, tracker, kind, model in itertools.product(
        np.unique(edges.method), np.unique(edges.tracker), np.unique(edges.kind), np.unique(edges.model)
    ):
        m = held & (edges.method == method) & (edges.tracker == tracker) & (edges.kind == kind) & (edges.model == model)
        if m.any():
            print(f"| {method} | {tracker} | {kind} | {model} | {summary(scaled[m])} |")
    tails(edges, scaled, adopted)


def tails(edges: Edges, scaled: np.ndarray, factors: dict) -> None:
    """What the edges above the 99 % bound are made of (report data, fitted runs, with the factors)."""
    held = (edges.split == "held-out") & edges.fitted
    print(
        "\n## The tail (report data, fitted runs, with the factors): share above 11.345 per bin, and its share of"
        " the tail\n"
    )
    print("| method | quantity | bin | above 11.345 in the bin | share of the tail | edges |")
    print("|---|---|---|---|---|---|")
    bins = {
        "true step [deg]": (edges.gt_angle_deg, (0, 0.5, 1, 2, 4, 8, 1e9)),
        "baseline [mm]": (edges.gt_baseline_m * 1e3, (0, 1, 3, 10, 30, 1e9)),
        "error [px of focal length]": (edges.error_px, (0, 0.7, 3.5, 1e9)),
        "predicted sigma [px], with the factor": (
            edges.sigma_px * np.sqrt([factors.get((m, f), 1.0) for m, f in zip(edges.method, edges.family)]),
            (0, 0.5, 1, 2, 4, 1e9),
        ),
        "inliers": (edges.inliers, (0, 15, 30, 60, 120, 1e9)),
    }
    for method in np.unique(edges.method[held]):
        base = held & (edges.method == method)
        tail = base & (scaled > CHI2_P99)
        for name, (values, cuts) in bins.items():
            for lo, hi in zip(cuts[:-1], cuts[1:]):
                m = base & (values >= lo) & (values < hi)
                if m.any():
                    print(
                        f"| {method} | {name} | {lo:g}-{hi:g} | {np.mean(scaled[m] > CHI2_P99):.1%} | "
                        f"{(tail & m).sum() / max(tail.sum(), 1):.0%} | {m.sum()} |"
                    )
        for label in ("kind", "model", "config", "frontend"):
            values = getattr(edges, label)
            for v in np.unique(values[base]):
                m = base & (values == v)
                print(
                    f"| {method} | {label} | {v} | {np.mean(scaled[m] > CHI2_P99):.1%} | "
                    f"{(tail & m).sum() / max(tail.sum(), 1):.0%} | {m.sum()} |"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser, "the real recording ('' to leave it out)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[41, 42, 43], help="report simulator seeds")
    parser.add_argument("--only", nargs="*", metavar="LABEL", help="run only these data (e.g. 'seed 41')")
    parser.add_argument("--methods", nargs="*", default=list(cov_module.METHODS), help="covariance methods")
    parser.add_argument("--rows", type=Path, help="write every edge to this CSV file")
    parser.add_argument("--from", dest="sources", type=Path, nargs="*", help="read the edges from these CSV files")
    parser.add_argument("--threads", type=int, default=1, help="eas-vo's threads (default 1)")
    args = parser.parse_args()
    real = str(real_folder(args.real)) if args.real else ""
    concurrency.set_threads(args.threads)
    if args.sources:
        rows = [row for source in args.sources for row in read_rows(source)]
    else:
        models, rows = tagging(), []
        for spec in runs(real, args.seeds, args.only):
            label, split, _, tracker, file, frontend, _ = spec
            for method in methods_of(tracker, args.methods):
                rows += edge_rows(models, *spec, method)
                print(
                    f"{label} ({split}) {tracker} {file} {frontend} {method}: {len(rows)} edges",
                    file=sys.stderr,
                    flush=True,
                )
                if args.rows:
                    with open(args.rows, "w", newline="") as f:
                        writer = csv.DictWriter(f, FIELDS)
                        writer.writeheader()
                        writer.writerows(rows)
    edges = Edges(rows)
    if not edges.fitted.any():
        print("no fitted run: no factor fitted, no method chosen")
        report(edges, {}, {})
        return
    exact, adopted = fit(edges, reference=False), fit(edges, reference=True)
    print(f"factor rule: {SCALE_RULE}; kept outside [{1 / KEEP_WITHIN:.2f}, {KEEP_WITHIN}]")
    for key in sorted(adopted):
        print(f"factor {' '.join(key)}: {adopted[key]:.3g} with the reference's noise, {exact[key]:.3g} without")
    print(f"method rule: {METHOD_RULE}")
    for name, factors, reference in (("reference noise added", adopted, True), ("exact reference", exact, False)):
        print(f"chosen ({name}): {choose_method(edges, factors, reference)}")
    report(edges, exact, adopted)
    misses(edges)


if __name__ == "__main__":
    main()
