"""Direct photometric alignment of two views of a rotating camera: how well a rotation explains
the two images (the zero-mean normalised cross-correlation of one image warped onto the other),
and a rotation found from the intensities alone, where tracked points fail (motion blur that
differs between the two frames defeats LK's small patches, not an alignment of whole images).
Not a plugin.

Both work on undistorted images (the pinhole camera of the same K), where a rotation R_i_j is
exactly the homography K R_i_j K^-1 from view j to view i, whatever the scene's depth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numba
import numpy as np

from eas_vo import concurrency
from eas_vo.camera import CameraModel
from eas_vo.geometry.compiled import exp_so3
from eas_vo.geometry.covariance import MIN_VARIANCE, UNDETERMINED_VARIANCE
from eas_vo.geometry.rotations import geodesic_angle, rotvec_to_matrix, scaled_rotation

#: Focal lengths [px] of the resolutions the alignment and the score work at, whatever the
#: sensor: each view is resized to them, so every figure below in pixels of a resolution is an
#: angle (a pixel at 25 px of focal length spans 2.3 deg). Coarse to fine: the coarsest still
#: holds a shape, its basin spans several of its pixels, tens of degrees (a lost track's);
#: the finest's half pixel (0.3 deg) is well below a failed track's error, and it averages
#: the noise. Equal to an eighth, a quarter and half of the DAVIS240's 200 px.
ALIGN_FOCAL_PX = (25.0, 50.0, 100.0)
SCORE_FOCAL_PX = 100.0
#: What the alignment can be held to [rad]: a pixel of its finest resolution (0.57 deg). Two
#: rotations further apart than that are two different answers, not the same one measured twice.
FINEST_PIXEL_RAD = 1.0 / ALIGN_FOCAL_PX[-1]
#: Blur [px of the coarsest resolution] where the search ranks its first candidates: it widens the
#: score's peak beyond the grid's half step for scenes of fine texture.
SEARCH_BLUR_PX = 1.0
#: Pans and tilts [deg] scored at the coarsest resolution besides the given starts: as far as a
#: fast hand-held turn goes between every other frame, in steps that stay inside the score's
#: basin at that resolution (3.3 px); each with these rolls [deg] (half their step moves the
#: DAVIS240's view's edges by about as much as half a step of pan). docs/best_config.md, "How
#: the fallback works", says which speed the span covers.
SEARCH_GRID_DEG = np.arange(-45.0, 45.1, 7.5)
SEARCH_ROLL_DEG = (-15.0, 0.0, 15.0)
#: How many candidates go on to each resolution of ALIGN_FOCAL_PX (the best-scoring after the last).
SEARCH_KEEP = (8, 2, 1)
#: Gauss-Newton steps at each resolution, each candidate's stopping sooner once a step of it moves
#: the view by under ALIGN_STOP_PX pixels of that resolution.
ALIGN_ITERATIONS = 10
ALIGN_STOP_PX = 0.01
#: The most rows (24 bytes each) of the search grid's warps tabulated once per camera (_Level.warps);
#: a view wider than that (over 2000 pixels at the coarsest resolution) projects the grid
#: pixel by pixel for every pair instead, with the same scores.
GRID_TABLE_MAX_ROWS = 2_000_000
#: The covariance of an alignment counts the residuals' correlation between pixels up to this
#: many pixels apart along each axis of its resolution (_correlated_information): what an
#: interpolation, a resize by a factor other than a power of two or a smoothing frontend
#: spreads a pixel's noise over.
CORRELATION_LAGS = 2
#: The step [px of the finest resolution] of the central differences by which the covariance
#: of an alignment differentiates its estimating equation (_sensitivity): small beside a pixel,
#: large beside the rounding of the views' float32 values.
SENSITIVITY_STEP_PX = 0.01
#: Rotations scored per thread at the least (the search's hundreds are split across the cores).
PARALLEL_CANDIDATES = 64
#: The overlap below which two views share too little to be scored [fraction of the view].
MIN_OVERLAP = 0.2
#: A rotation explains two views only where it leaves at most this fraction of the mismatch
#: (1 - score) that no motion leaves: what beats no motion by less is what noise, a sensor's
#: fixed pattern or a featureless view give (docs/best_config.md, "How the fallback works", has
#: what wrong and right alignments leave).
IDENTITY_MARGIN = 0.7


#: A run stops using a fallback once more than half of its judged steps, and at least
#: AUDIT_MIN_JUDGED of them, disagree with the primary measurements beside them (FallbackAudit).
#: A right fallback's steps disagree only where the motion itself changes by more than the bound
#: between two frames, a minority of the steps at hand-held speeds, so that at least 10 judged
#: steps turn a right fallback off only rarely (docs/best_config.md, "How the fallback works",
#: has how often the motion does so and the chance).
AUDIT_MIN_JUDGED = 10


@dataclass
class FallbackAudit:
    """A fallback judged over a run by the primary tracker's own steps: each step the fallback
    gave (frame k, R_{k-1}_{k}) is compared with the constant-velocity extrapolation of the
    primary (not weak) step of frame k-1 and of frame k+1 where there is one. It agrees when it lies
    within FINEST_PIXEL_RAD plus the extrapolation's own angle of one of them (the neighbour
    explains it better than no motion does). Once more than half of at least
    AUDIT_MIN_JUDGED judged steps disagree, the fallback is `off` for the rest of the run and
    `warning` says so, naming the frames."""

    name: str
    off: bool = False
    warning: str = ""
    judged: list = field(default_factory=list)  # (frame, whether it agreed)
    _now: int = 0  # the frame observed last
    _previous: tuple | None = None  # the last frame's (index, kind, R_{k-1}_{k}, dt [s])
    _waiting: tuple | None = None  # a fallback step not yet compared with its next frame: (k, R, dt, distances)

    def observe(self, k: int, kind: str, R_prev_cur: np.ndarray | None, dt_s: float) -> None:
        """Frame k's step from frame k-1 over `dt_s` [s]: `kind` "primary" (a step of the primary
        tracker that is not weak), "fallback" (the fallback's step) or "other" (none, or weak:
        no evidence either way)."""
        self._now = k
        if self._waiting is not None:
            j, R, dt, distances = self._waiting
            self._waiting = None
            if kind == "primary" and k == j + 1:
                distances.append(self._distance(R, dt, R_prev_cur, dt_s))
            self._judge(j, distances)
        if kind == "fallback" and not self.off:
            previous = self._previous
            adjacent = previous is not None and previous[0] == k - 1 and previous[1] == "primary"
            self._waiting = k, R_prev_cur, dt_s, [self._distance(R_prev_cur, dt_s, *previous[2:])] if adjacent else []
        self._previous = k, kind, R_prev_cur, dt_s

    @staticmethod
    def _distance(R: np.ndarray, dt_s: float, R_neighbour: np.ndarray, dt_neighbour_s: float) -> float:
        """How far R lies from the neighbour's extrapolation to dt_s, in units of the bound
        (FINEST_PIXEL_RAD plus the extrapolation's own angle): above 1 disagrees."""
        expected = scaled_rotation(R_neighbour, dt_s / dt_neighbour_s)
        return float(geodesic_angle(expected, R) / (FINEST_PIXEL_RAD + geodesic_angle(np.eye(3), expected)))

    def _judge(self, k: int, distances: list[float]) -> None:
        """Frame k's fallback step agrees when one of `distances` is at most 1; the run's verdict."""
        if not distances or self.off:
            return
        self.judged.append((k, min(distances) <= 1.0))
        against = [j for j, agreed in self.judged if not agreed]
        if len(self.judged) >= AUDIT_MIN_JUDGED and 2 * len(against) > len(self.judged):
            self.off = True
            frames = ", ".join(str(j) for j in against)
            self.warning = (
                f"the {self.name} fallback is off from frame {self._now + 1}: {len(against)} of the {len(self.judged)} "
                f"steps of it judged disagree with the measurements beside them (frames {frames})"
            )


class PhotometricAlignment:
    """Scores and finds rotations between two uint8 images of `camera` by their intensities."""

    def __init__(self, camera: CameraModel):
        self._maps = camera.undistort_maps()
        seen = self._undistort(np.full((camera.height, camera.width), 255, np.uint8)) == 255
        self._levels = {f: _Level(camera, seen, f) for f in sorted({SCORE_FOCAL_PX, *ALIGN_FOCAL_PX})}
        self._grid = np.array(
            [
                rotvec_to_matrix(np.radians([tilt, pan, roll]))
                for roll in SEARCH_ROLL_DEG
                for pan in SEARCH_GRID_DEG
                for tilt in SEARCH_GRID_DEG
            ]
        )
        self._grid_warps = self._levels[ALIGN_FOCAL_PX[0]].warps(self._grid)  # the same for every pair of views
        # the last pair of views scored and its scores by rotation (one tracker's, not shared across threads)
        self._scored: tuple[dict, dict, dict] | None = None

    def _undistort(self, image: np.ndarray) -> np.ndarray:
        return cv2.remap(image, *self._maps, cv2.INTER_LINEAR)

    def pyramid(self, image: np.ndarray) -> dict:
        """`image` undistorted at each resolution the alignment and the score use (keyed by
        their focal lengths [px]), and the coarsest blurred by SEARCH_BLUR_PX (key "search"),
        float32; under "pixels", the same keys: each one's pixels of the view (_Level.ys, xs)."""
        flat = self._undistort(image).astype(np.float32)
        levels: dict = {f: level.resized(flat) for f, level in self._levels.items()}
        levels["search"] = cv2.GaussianBlur(levels[ALIGN_FOCAL_PX[0]], (0, 0), SEARCH_BLUR_PX)
        coarsest = self._levels[ALIGN_FOCAL_PX[0]]
        levels["pixels"] = {f: levels[f][level.ys, level.xs] for f, level in self._levels.items()}
        levels["pixels"]["search"] = levels["search"][coarsest.ys, coarsest.xs]
        return levels

    def score(self, source: dict, image: dict, R_source_image: np.ndarray) -> float:
        """How well R_source_image explains the two views (their `pyramid`s): the zero-mean
        normalised cross-correlation of `source` warped into `image`'s view with `image`, over
        the pixels both see (at SCORE_FOCAL_PX); -1 when they share under MIN_OVERLAP of the view
        or either is flat there. Each rotation of the last pair of views is scored once."""
        if self._scored is None or self._scored[0] is not source or self._scored[1] is not image:
            self._scored = source, image, {}
        scores, key = self._scored[2], np.asarray(R_source_image, float).tobytes()
        if key not in scores:
            f = SCORE_FOCAL_PX
            scores[key] = float(self._levels[f].scores([source[f]], [image["pixels"][f]], R_source_image[None])[0, 0])
        return scores[key]

    def explains(self, source: dict, image: dict, R_source_image: np.ndarray) -> bool:
        """Whether R_source_image explains the two views (`pyramid`s) clearly better than no
        motion: its score leaves at most IDENTITY_MARGIN of the mismatch (1 - score) that the
        identity's leaves, and the views share enough to be scored."""
        score = self.score(source, image, R_source_image)
        return score > -1.0 and 1.0 - score <= IDENTITY_MARGIN * (1.0 - self.score(source, image, np.eye(3)))

    def align(self, source: dict, image: dict, starts: list[np.ndarray]) -> np.ndarray | None:
        """R_source_image found from the intensities (`pyramid`s): `starts` and the grid of
        SEARCH_GRID_DEG and SEARCH_ROLL_DEG scored at the coarsest resolution, the best
        SEARCH_KEEP[0] (half by the sharp image's score, half by the blurred one's) refined
        there by Gauss-Newton on the rotation's three angles, the best SEARCH_KEEP[1] of those
        at the next resolution, and so on; the best of the last. None where it does not
        explain the views clearly better than no motion (`explains`)."""
        candidates = np.concatenate([np.asarray(starts, float).reshape(-1, 3, 3), self._grid])
        for f, keep in zip(ALIGN_FOCAL_PX, SEARCH_KEEP):
            level = self._levels[f]
            if f == ALIGN_FOCAL_PX[0]:  # half ranked sharp, half blurred
                pair = [source[f], source["search"]], [image["pixels"][f], image["pixels"]["search"]]
                n_starts = len(candidates) - len(self._grid)
                grid = (
                    level.scores(*pair, self._grid)
                    if self._grid_warps is None
                    else level.warped_scores(*pair, self._grid_warps)
                )
                scores = np.concatenate([level.scores(*pair, candidates[:n_starts]), grid], axis=1)
                sharp, blurred = np.argsort(-scores)
                order = list(dict.fromkeys([*sharp[: keep // 2], *blurred[:keep], *sharp]))[:keep]
            else:
                order = np.argsort(-level.scores([source[f]], [image["pixels"][f]], candidates)[0])[:keep]
            candidates = level.refine(source[f], image[f], image["pixels"][f], candidates[np.asarray(order)])
        last = ALIGN_FOCAL_PX[-1]
        best = candidates[0]
        if len(candidates) > 1:
            best = candidates[
                int(np.argmax(self._levels[last].scores([source[last]], [image["pixels"][last]], candidates)[0]))
            ]
        return best if self.explains(source, image, best) else None

    def covariance(self, source: dict, image: dict, R_source_image: np.ndarray) -> np.ndarray:
        """The covariance [rad^2] (3, 3) of R_source_image found by `align` (its optimum), in
        RelativeRotation's convention (the right perturbation in the image's frame: a rotation
        of the image view's bearings), from the photometric cost at the finest resolution, where
        the refinement stops at the zero of its Gauss-Newton gradient psi = J^T r (J the
        target's derivative by the rotation's angles, `_Level.jacobian`, r the normalised
        residuals over the n pixels both views see): the sandwich A^-1 M A^-T, A the derivative
        of psi by the rotation (_sensitivity) and M the covariance of psi
        (_correlated_information, times n / (n - 3)). With independent residuals and J the
        residuals' own derivative it is the textbook's sigma_r^2 (J^T J)^-1, sigma_r^2 =
        sum r^2 / (n - 3); neither holds here: neighbouring residuals are correlated, and J
        carries the target's noise (docs/best_config.md, "How the fallback works", has what each
        form gives). UNDETERMINED_VARIANCE on every axis where it is undetermined (under
        MIN_OVERLAP shared, a flat view, a singular A); every variance between MIN_VARIANCE and
        UNDETERMINED_VARIANCE."""
        f = ALIGN_FOCAL_PX[-1]
        level = self._levels[f]
        target = image["pixels"][f]
        level._check([source[f]], [target])
        sampled, R = np.asarray(source[f], np.float32), np.asarray(R_source_image, float)
        h = SENSITIVITY_STEP_PX / level.K[0, 0]
        turned = [R @ rotvec_to_matrix(sign * h * e) for e in np.eye(3) for sign in (1.0, -1.0)]
        samples = [_sampled(sampled, level.K @ R_turned, level.bearings, level.seen) for R_turned in [R, *turned]]
        inside = np.logical_and.reduce([seen for seen, _ in samples])  # at every rotation sampled
        target = np.asarray(target, float)
        undetermined = UNDETERMINED_VARIANCE * np.eye(3)
        n = int(inside.sum())
        if n < max(level.min_count, 4) or samples[0][1][inside].std() == 0 or target[inside].std() == 0:
            return undetermined
        J = level.jacobian(image[f])
        A = _sensitivity(inside, [values for _, values in samples[1:]], target, J, h)
        M = _correlated_information(level, inside, samples[0][1], target, J) * n / (n - 3)
        if not np.all(np.isfinite(A)) or np.linalg.matrix_rank(A) < 3:
            return undetermined
        A_inv = np.linalg.inv(A)
        lam, V = np.linalg.eigh(A_inv @ (0.5 * (M + M.T)) @ A_inv.T)
        if not np.all(np.isfinite(lam)):
            return undetermined
        return (V * np.clip(lam, MIN_VARIANCE, UNDETERMINED_VARIANCE)) @ V.T


def _normalised(values: np.ndarray) -> np.ndarray:
    return (values - values.mean()) / values.std()


def _sensitivity(inside: np.ndarray, turned: list, target: np.ndarray, J: np.ndarray, h: float) -> np.ndarray:
    """The derivative (3, 3) of the refinement's estimating equation psi = sum_k J_k r_k = 0 (its
    Gauss-Newton gradient, zero at the optimum; J (N, 3) the target's derivative by the
    rotation's angles over its std, r the normalised residuals over the `inside` pixels) by the
    right perturbation of the rotation: central differences from the source's values sampled at
    the rotation turned by +h and -h [rad] about x, y and z in turn (`turned`, six (N,) arrays),
    through the bilinear sampling. The textbook's J^T J stands for it where the target's
    gradient is the residual's own; with noise it holds the target's gradient noise twice and
    overstates the information by as much as the noise's gradients weigh beside the scene's
    (the source's noise enters the residual's derivative, the target's J)."""
    t = target[inside]
    Jn = J[inside] / t.std()

    def psi(values: np.ndarray) -> np.ndarray:
        return Jn.T @ (_normalised(values[inside]) - _normalised(t))

    return np.column_stack([(psi(turned[2 * i]) - psi(turned[2 * i + 1])) / (2 * h) for i in range(3)])


def _correlated_information(
    level: "_Level", inside: np.ndarray, values: np.ndarray, target: np.ndarray, J: np.ndarray
) -> np.ndarray:
    """The covariance (3, 3) of J^T r, the Gauss-Newton gradient, over the view's `inside` pixels
    at `level`: r the residuals (the normalised `values` of the source sampled there minus the
    normalised `target`), J (N, 3) the target's derivative by the rotation's angles over the
    target's std (the normalised target's). Sum over pixel offsets d up to CORRELATION_LAGS
    along each axis of the residuals' autocovariance at d times sum_k J_k J_{k+d}^T (a
    heteroscedasticity and autocorrelation consistent estimate: Newey and West, Econometrica
    55(3), 1987, without their taper). Independent residuals give sigma_r^2 J^T J; the bilinear
    sampling of the source alone correlates neighbouring residuals (it lowers a pixel's variance,
    not the noise's power at the scales J varies on), and so do a resize by a factor other than a
    power of two, an undistortion and a smoothing frontend."""
    v, t = values[inside], target[inside]
    r = np.zeros(level.shape)
    Jn = np.zeros((*level.shape, 3))
    valid = np.zeros(level.shape, bool)
    ys, xs = level.ys[inside], level.xs[inside]
    r[ys, xs] = _normalised(v) - _normalised(t)
    Jn[ys, xs] = J[inside] / t.std()
    valid[ys, xs] = True
    h, w = level.shape
    L = CORRELATION_LAGS
    M = np.zeros((3, 3))
    for dy in range(-L, L + 1):
        for dx in range(-L, L + 1):
            a = (slice(max(0, -dy), h - max(0, dy)), slice(max(0, -dx), w - max(0, dx)))
            b = (slice(max(0, dy), h - max(0, -dy)), slice(max(0, dx), w - max(0, -dx)))
            both = valid[a] & valid[b]
            if both.any():
                gamma = float(np.mean(r[a][both] * r[b][both]))
                M += gamma * Jn[a][both].T @ Jn[b][both]
    return M


class _Level:
    """One resolution of the undistorted views, `focal_px` [px] of focal length along each axis
    (the sensor's at most; pixels that are not square become square): the image view's pixels
    (those the lens sees, `seen` at the sensor's size) as bearings, for scoring and refining
    rotations there."""

    def __init__(self, camera: CameraModel, seen: np.ndarray, focal_px: float):
        fx, fy = camera.K[0, 0], camera.K[1, 1]
        self.size = (
            max(round(camera.width * min(focal_px / fx, 1.0)), 2),
            max(round(camera.height * min(focal_px / fy, 1.0)), 2),
        )
        sx, sy = self.size[0] / camera.width, self.size[1] / camera.height
        # cv2.resize keeps pixel centres in place: x' + 0.5 = sx (x + 0.5)
        self.K = np.array([[sx, 0.0, 0.5 * (sx - 1.0)], [0.0, sy, 0.5 * (sy - 1.0)], [0.0, 0.0, 1.0]]) @ camera.K
        self.seen = self.resized(seen.astype(np.uint8) * 255) == 255
        self.shape = self.seen.shape
        self.ys, self.xs = np.nonzero(self.seen)
        self.bearings = np.linalg.inv(self.K) @ np.stack([self.xs, self.ys, np.ones_like(self.xs)]).astype(
            float
        )  # (3, N)
        self.min_count = max(MIN_OVERLAP * len(self.xs), 1.0)  # pixels two views must share to be compared

    def _check(self, sources: list[np.ndarray], targets: list[np.ndarray]) -> None:
        """Views of this resolution, as the compiled kernels' unchecked indexing needs."""
        if any(s.shape != self.shape for s in sources) or any(t.shape != self.xs.shape for t in targets):
            raise ValueError(f"views of {self.shape[1]}x{self.shape[0]} px expected (another camera's pyramid?)")

    def resized(self, image: np.ndarray) -> np.ndarray:
        """`image` (the sensor's size) at this resolution."""
        return cv2.resize(image, self.size, interpolation=cv2.INTER_AREA)

    def warps(self, Rs: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """Where each rotation of Rs (C, 3, 3) takes the image view's pixels in a source view,
        for `warped_scores`: (first (C + 1): each rotation's rows start, pixel (M): the image
        view's pixel, corner (M): the source pixel at the top left of its four (row-major
        index), offsets (M, 2): the point's from that pixel [px]), rows only where the view's
        pixels land inside the source and its lens saw them, none for a rotation with under
        min_count; None beyond GRID_TABLE_MAX_ROWS rows."""
        KRs = np.asarray(self.K @ Rs, np.float64)
        first = np.zeros(len(Rs) + 1, np.int64)
        table = np.empty(0, np.uint32), np.empty(0, np.uint32), np.empty((0, 2))
        _warp_rows(KRs, self.bearings, self.seen, self.min_count, first, *table, False)
        if first[-1] > GRID_TABLE_MAX_ROWS:
            return None
        table = np.empty(first[-1], np.uint32), np.empty(first[-1], np.uint32), np.empty((first[-1], 2))
        _warp_rows(KRs, self.bearings, self.seen, self.min_count, first, *table, True)
        return (first, *table)

    def warped_scores(
        self, sources: list[np.ndarray], targets: list[np.ndarray], warps: tuple[np.ndarray, ...]
    ) -> np.ndarray:
        """`scores` of the rotations whose `warps` are given: the same numbers, without projecting."""
        return self._each_pair(
            sources,
            targets,
            len(warps[0]) - 1,
            lambda source, target, a, b: _zncc_warped(
                source.reshape(-1), target, warps[0][a : b + 1], *warps[1:], self.shape[1], self.min_count
            ),
        )

    def scores(self, sources: list[np.ndarray], targets: list[np.ndarray], Rs: np.ndarray) -> np.ndarray:
        """The ZNCC of each image's pixels of the view `targets` (its `pyramid`'s "pixels") with
        the same-index image of `sources` (float32, this resolution) warped by each rotation of
        Rs (C, 3, 3), over the pixels both see: (len(targets), C); -1 where they share under
        MIN_OVERLAP or either is flat there."""
        KRs = np.asarray(self.K @ Rs, np.float64)
        return self._each_pair(
            sources,
            targets,
            len(KRs),
            lambda source, target, a, b: _zncc(source, target, KRs[a:b], self.bearings, self.seen, self.min_count),
        )

    def _each_pair(self, sources: list[np.ndarray], targets: list[np.ndarray], count: int, kernel) -> np.ndarray:
        """kernel(source, target, a, b), the scores of candidates a..b-1, for each pair of views,
        the candidates split across the threads: (len(targets), count)."""
        self._check(sources, targets)
        return np.stack(
            [
                np.concatenate(concurrency.split(lambda a, b: kernel(source, target, a, b), count, PARALLEL_CANDIDATES))
                for source, target in zip(sources, targets)
            ]
        )

    def jacobian(self, image: np.ndarray) -> np.ndarray:
        """The derivative (N, 3) of `image` (this resolution) at the view's pixels by the angles of
        a rotation of its bearings, d image(pi(K exp([d]x) b)) / d d at d = 0 (Sobel gradients)."""
        gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)[self.ys, self.xs] / 8
        gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)[self.ys, self.xs] / 8
        X, Y = self.bearings[0], self.bearings[1]  # z = 1
        fx, fy = self.K[0, 0], self.K[1, 1]
        # d image(pi(K exp([d]x) b)) / d d at d = 0 is r (-[b]x), r = grad . d pi / d b
        r0, r1, r2 = gx * fx, gy * fy, -(gx * fx * X + gy * fy * Y)
        return np.ascontiguousarray(np.stack([r2 * Y - r1, r0 - r2 * X, r1 * X - r0 * Y], axis=1))

    def refine(self, source: np.ndarray, image: np.ndarray, target: np.ndarray, Rs: np.ndarray) -> np.ndarray:
        """Each R_source_image of Rs (C, 3, 3) refined by inverse-compositional Gauss-Newton on
        the squared difference of the two views (each normalised to zero mean and unit variance
        over the pixels both see), up to ALIGN_ITERATIONS steps, each stopping once its step
        moves the view by under ALIGN_STOP_PX at this resolution. `target`: the image's pixels
        of the view (its `pyramid`'s "pixels")."""
        self._check([source], [target])
        return _refine(
            np.asarray(source, np.float32),
            target,
            self.jacobian(image),
            self.K,
            np.array(Rs, float),
            self.bearings,
            self.seen,
            self.min_count,
            ALIGN_ITERATIONS,
            ALIGN_STOP_PX / self.K[0, 0],
        )


@numba.njit(cache=True, nogil=True, inline="always")
def _project(M, bearings, n, seen):
    """Where the homography M puts bearing n of `bearings` (3, N) in an image of seen's size:
    (whether it is inside: ahead of the camera, inside the image and where the lens saw,
    `seen`; u, v [px])."""
    h, w = seen.shape
    bx, by, bz = bearings[0, n], bearings[1, n], bearings[2, n]
    z = M[2, 0] * bx + M[2, 1] * by + M[2, 2] * bz
    ahead = z > 1e-6
    if not ahead:
        z = 1.0  # u, v unused
    u = (M[0, 0] * bx + M[0, 1] * by + M[0, 2] * bz) / z
    v = (M[1, 0] * bx + M[1, 1] * by + M[1, 2] * bz) / z
    return ahead and u >= 0 and v >= 0 and u <= w - 1 and v <= h - 1 and seen[int(v + 0.5), int(u + 0.5)], u, v


@numba.njit(cache=True, nogil=True, inline="always")
def _corner(u, v, image):
    """The top-left pixel i, j of the four around (u, v) [px] inside `image` (h, w), and the
    offsets a, b from it (bilinear weights)."""
    h, w = image.shape
    i, j = min(int(u), w - 2), min(int(v), h - 2)
    return i, j, u - i, v - j


@numba.njit(cache=True, nogil=True, inline="always")
def _bilinear(image, u, v):
    """`image` (h, w) at (u, v) [px] inside it, interpolated bilinearly (float64)."""
    i, j, a, b = _corner(u, v, image)
    i, j, one = np.uint32(i), np.uint32(j), np.uint32(1)  # unsigned: no negative-index handling
    return (
        (1 - a) * (1 - b) * image[j, i]
        + a * (1 - b) * image[j, i + one]
        + (1 - a) * b * image[j + one, i]
        + a * b * image[j + one, i + one]
    )


@numba.njit(cache=True, nogil=True)
def _warp_rows(KRs, bearings, seen, min_count, first, pixel, corner, offsets, fill):
    """_Level.warps' table of the homographies KRs (C, 3, 3), in two calls: without `fill`,
    where each rotation's rows start, first (C + 1) (no rows under min_count); then with
    `fill`, the rows, into arrays of first[-1] rows."""
    w = seen.shape[1]
    for c in range(KRs.shape[0]):
        if fill and first[c + 1] == first[c]:
            continue
        m = first[c]
        for n in range(bearings.shape[1]):
            inside, u, v = _project(KRs[c], bearings, n, seen)
            if not inside:
                continue
            if fill:
                i, j, a, b = _corner(u, v, seen)
                pixel[m], corner[m], offsets[m, 0], offsets[m, 1] = n, j * w + i, a, b
            m += 1
        if not fill:
            first[c + 1] = m if m - first[c] >= min_count else first[c]


@numba.njit(cache=True, nogil=True)
def _zncc_warped(source, target, first, pixel, corner, offsets, w, min_count):
    """_zncc of the rotations whose warp table (_Level.warps) is given, `source` (h * w)
    row-major: the same sums in the same order, so the same scores."""
    C = len(first) - 1
    out = np.full(C, -1.0)
    w, one = np.uint32(w), np.uint32(1)  # unsigned indices: no negative-index handling
    for c in range(C):
        count = first[c + 1] - first[c]
        if count < min_count:
            continue
        sx = sy = sxx = syy = sxy = 0.0
        for m in range(first[c], first[c + 1]):
            k, a, b = corner[m], offsets[m, 0], offsets[m, 1]
            x = (
                (1 - a) * (1 - b) * source[k]
                + a * (1 - b) * source[k + one]
                + (1 - a) * b * source[k + w]
                + a * b * source[k + w + one]
            )
            y = target[pixel[m]]
            sx += x
            sy += y
            sxx += x * x
            syy += y * y
            sxy += x * y
        out[c] = _correlation(sx, sy, sxx, syy, sxy, count)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _correlation(sx, sy, sxx, syy, sxy, count):
    """The correlation coefficient of `count` pairs (x, y) from their sums; -1 where either is flat."""
    vx, vy = sxx - sx * sx / count, syy - sy * sy / count
    return (sxy - sx * sy / count) / np.sqrt(vx * vy) if vx > 0 and vy > 0 else -1.0


@numba.njit(cache=True, nogil=True)
def _gauss_newton_steps(source, target, J, KRs, bearings, seen, min_count):
    """One inverse-compositional Gauss-Newton step (C, 3) for each homography K R_c (C, 3, 3):
    `source` (h, w) sampled where K R_c puts the image view's bearings (3, N), both it and
    `target` (N) normalised to zero mean and unit variance over the pixels both see, `J` (N, 3)
    the target's derivative by the rotation's angles. Zero where under `min_count` pixels are
    shared or either view is flat there."""
    C, N = KRs.shape[0], bearings.shape[1]
    deltas = np.zeros((C, 3))
    for c in range(C):
        # in one pass over the pixels both see: the sums of v, v^2, t, t^2, J, v J, t J and J J^T
        # (symmetric), from which the residual r = (v - mean v) / std v - (t - mean t) / std t gives J^T r
        n = 0
        sv = svv = st = stt = 0.0
        s0 = s1 = s2 = v0 = v1 = v2 = t0 = t1 = t2 = h00 = h01 = h02 = h11 = h12 = h22 = 0.0
        for k in range(N):
            ok, u, v = _project(KRs[c], bearings, k, seen)
            if not ok:
                continue
            x = _bilinear(source, u, v)
            y, j0, j1, j2 = np.float64(target[k]), J[k, 0], J[k, 1], J[k, 2]
            n += 1
            sv, svv, st, stt = sv + x, svv + x * x, st + y, stt + y * y
            s0, s1, s2 = s0 + j0, s1 + j1, s2 + j2
            v0, v1, v2 = v0 + x * j0, v1 + x * j1, v2 + x * j2
            t0, t1, t2 = t0 + y * j0, t1 + y * j1, t2 + y * j2
            h00, h01, h02 = h00 + j0 * j0, h01 + j0 * j1, h02 + j0 * j2
            h11, h12, h22 = h11 + j1 * j1, h12 + j1 * j2, h22 + j2 * j2
        if n < min_count:
            continue
        v_mean, t_mean = sv / n, st / n
        v_var, t_var = svv / n - v_mean * v_mean, stt / n - t_mean * t_mean
        if v_var <= 0.0 or t_var <= 0.0:
            continue
        v_std, t_std = np.sqrt(v_var), np.sqrt(t_var)
        g0 = (v0 - v_mean * s0) / v_std - (t0 - t_mean * s0) / t_std
        g1 = (v1 - v_mean * s1) / v_std - (t1 - t_mean * s1) / t_std
        g2 = (v2 - v_mean * s2) / v_std - (t2 - t_mean * s2) / t_std
        H = np.array([[h00, h01, h02], [h01, h11, h12], [h02, h12, h22]]) / (t_std * t_std) + 1e-9 * np.eye(3)
        deltas[c] = np.linalg.solve(H, np.array([g0, g1, g2]) / t_std)
    return deltas


@numba.njit(cache=True, nogil=True)
def _sampled(source, KR, bearings, seen):
    """`source` (h, w) sampled (bilinear) where the homography K R (3, 3) puts the image view's
    bearings (3, N): (whether each is inside and its lens saw it (N,), the values (N,))."""
    N = bearings.shape[1]
    inside, values = np.zeros(N, np.bool_), np.zeros(N)
    for k in range(N):
        ok, u, v = _project(KR, bearings, k, seen)
        if ok:
            inside[k], values[k] = True, _bilinear(source, u, v)
    return inside, values


@numba.njit(cache=True, nogil=True)
def _refine(source, target, J, K, Rs, bearings, seen, min_count, iterations, stop_rad):
    """_Level.refine's iterations: each rotation of Rs (C, 3, 3) updated in place by up to
    `iterations` _gauss_newton_steps (R <- R exp(-[d]x)), until a step of it is under
    `stop_rad` long."""
    moving = np.arange(len(Rs))
    for _ in range(iterations):
        KRs = np.empty((len(moving), 3, 3))
        for m, c in enumerate(moving):
            KRs[m] = K @ Rs[c]
        deltas = _gauss_newton_steps(source, target, J, KRs, bearings, seen, min_count)
        still = np.empty(len(moving), np.bool_)
        for m, c in enumerate(moving):
            Rs[c] = Rs[c] @ exp_so3(-deltas[m])
            still[m] = np.sqrt(deltas[m, 0] ** 2 + deltas[m, 1] ** 2 + deltas[m, 2] ** 2) >= stop_rad
        moving = moving[still]
        if len(moving) == 0:
            break
    return Rs


@numba.njit(cache=True, nogil=True)
def _zncc(source, target, KRs, bearings, seen, min_count):
    """scores (C): for each rotation c, the ZNCC of `target` (N, the image view's pixels) with
    `source` (h, w) sampled (bilinear) where K R_c puts the pixels' bearings (3, N), where the
    source's lens saw (`seen`, h x w); -1 with under `min_count` (at least 1) such pixels, or
    a flat image."""
    C, N = KRs.shape[0], bearings.shape[1]
    out = np.full(C, -1.0)
    for c in range(C):
        count = 0
        sx = sy = sxx = syy = sxy = 0.0
        for n in range(N):
            ok, u, v = _project(KRs[c], bearings, n, seen)
            if not ok:
                continue
            x = _bilinear(source, u, v)
            y = target[n]
            count += 1
            sx += x
            sy += y
            sxx += x * x
            syy += y * y
            sxy += x * y
        if count >= min_count:
            out[c] = _correlation(sx, sy, sxx, syy, sxy, count)
    return out
