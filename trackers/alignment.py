"""Direct photometric alignment of two views of a rotating camera: how well a rotation explains
the two images (the zero-mean normalised cross-correlation of one image warped onto the other),
and a rotation found from the intensities alone, where tracked points fail (motion blur that
differs between the two frames defeats LK's small patches, not an alignment of whole images).
Not a plugin.

Both work on undistorted images (the pinhole camera of the same K), where a rotation R_i_j is
exactly the homography K R_i_j K^-1 from view j to view i, whatever the scene's depth.
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from eas_vo import concurrency
from eas_vo.types import CameraModel

#: Focal lengths [px] of the resolutions the alignment and the score work at, whatever the
#: sensor: each view is resized to them, so every figure below in pixels of a resolution is an
#: angle (a pixel at 25 px of focal length spans 2.3 deg). Coarse to fine: the coarsest still
#: holds a shape, its basin spans several of its pixels, tens of degrees (a lost track's);
#: the finest's half pixel (0.3 deg) is well below a failed track's error, and it averages
#: the noise. Equal to an eighth, a quarter and half of the DAVIS240's 200 px.
ALIGN_FOCAL_PX = (25.0, 50.0, 100.0)
SCORE_FOCAL_PX = 100.0
#: Blur [px of the coarsest resolution] where the search ranks its first candidates: it widens the
#: score's peak beyond the grid's half step for scenes of fine texture.
SEARCH_BLUR_PX = 1.0
#: Pans and tilts [deg] scored at the coarsest resolution besides the given starts: the 43 deg
#: between frames of the real excerpt's p95 speed at half its frame rate, in steps of 7.5 deg
#: (3.3 px there, inside the basin); each with these rolls [deg] (half their step, 7.5 deg,
#: moves the DAVIS240's view's edges by about as much as half a step of pan).
SEARCH_GRID_DEG = np.arange(-45.0, 45.1, 7.5)
SEARCH_ROLL_DEG = (-15.0, 0.0, 15.0)
#: How many candidates go on to each resolution of ALIGN_FOCAL_PX (the best-scoring after the last).
SEARCH_KEEP = (8, 2, 1)
#: Gauss-Newton steps at each resolution, each run stopping sooner once a step moves the view by
#: under ALIGN_STOP_PX pixels of that resolution.
ALIGN_ITERATIONS = 10
ALIGN_STOP_PX = 0.01
#: Rotations scored per thread at the least (the search's hundreds are split across the cores).
PARALLEL_CANDIDATES = 64
#: The overlap below which two views share too little to be scored [fraction of the view].
MIN_OVERLAP = 0.2
#: A rotation explains two views only where it leaves at most this fraction of the mismatch
#: (1 - score) that no motion leaves: what beats no motion by less is what noise, a sensor's
#: fixed pattern or a featureless view give (on dim simulated frames 93 of the 109 alignments
#: more than 2 deg off leave more; on the real excerpt thinned to every 3rd frame the right
#: ones leave 0.02-0.64).
IDENTITY_MARGIN = 0.7


class PhotometricAlignment:
    """Scores and finds rotations between two uint8 images of `camera` by their intensities."""

    def __init__(self, camera: CameraModel):
        self._maps = camera.undistort_maps()
        seen = self._undistort(np.full((camera.height, camera.width), 255, np.uint8)) == 255
        self._levels = {f: _Level(camera, seen, f) for f in sorted({SCORE_FOCAL_PX, *ALIGN_FOCAL_PX})}
        self._grid = np.array([cv2.Rodrigues(np.radians([tilt, pan, roll]))[0]
                               for roll in SEARCH_ROLL_DEG for pan in SEARCH_GRID_DEG for tilt in SEARCH_GRID_DEG])

    def _undistort(self, image: np.ndarray) -> np.ndarray:
        return cv2.remap(image, *self._maps, cv2.INTER_LINEAR)

    def pyramid(self, image: np.ndarray) -> dict:
        """`image` undistorted at each resolution the alignment and the score use (keyed by
        their focal lengths [px]), and the coarsest blurred by SEARCH_BLUR_PX (key "search");
        float32."""
        flat = self._undistort(image).astype(np.float32)
        levels: dict = {f: level.resized(flat) for f, level in self._levels.items()}
        levels["search"] = cv2.GaussianBlur(levels[ALIGN_FOCAL_PX[0]], (0, 0), SEARCH_BLUR_PX)
        return levels

    def score(self, source: dict, image: dict, R_source_image: np.ndarray) -> float:
        """How well R_source_image explains the two views (their `pyramid`s): the zero-mean
        normalised cross-correlation of `source` warped into `image`'s view with `image`, over
        the pixels both see (at SCORE_FOCAL_PX); -1 when they share under MIN_OVERLAP of the view
        or either is flat there."""
        f = SCORE_FOCAL_PX
        return float(self._levels[f].scores([source[f]], [image[f]], R_source_image[None])[0, 0])

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
                sharp, blurred = np.argsort(-level.scores([source[f], source["search"]], [image[f], image["search"]], candidates))
                order = list(dict.fromkeys([*sharp[: keep // 2], *blurred[:keep], *sharp]))[:keep]
            else:
                order = np.argsort(-level.scores([source[f]], [image[f]], candidates)[0])[:keep]
            candidates = level.refine(source[f], image[f], candidates[np.asarray(order)])
        last = ALIGN_FOCAL_PX[-1]
        best = candidates[int(np.argmax(self._levels[last].scores([source[last]], [image[last]], candidates)[0]))]
        return best if self.explains(source, image, best) else None


class _Level:
    """One resolution of the undistorted views, `focal_px` [px] of focal length along each axis
    (the sensor's at most; pixels that are not square become square): the image view's pixels
    (those the lens sees, `seen` at the sensor's size) as bearings, for scoring and refining
    rotations there."""

    def __init__(self, camera: CameraModel, seen: np.ndarray, focal_px: float):
        fx, fy = camera.K[0, 0], camera.K[1, 1]
        self.size = (max(round(camera.width * min(focal_px / fx, 1.0)), 2), max(round(camera.height * min(focal_px / fy, 1.0)), 2))
        sx, sy = self.size[0] / camera.width, self.size[1] / camera.height
        # cv2.resize keeps pixel centres in place: x' + 0.5 = sx (x + 0.5)
        self.K = np.array([[sx, 0.0, 0.5 * (sx - 1.0)], [0.0, sy, 0.5 * (sy - 1.0)], [0.0, 0.0, 1.0]]) @ camera.K
        self.seen = self.resized(seen.astype(np.uint8) * 255) == 255
        self.shape = self.seen.shape
        self.ys, self.xs = np.nonzero(self.seen)
        self.bearings = np.linalg.inv(self.K) @ np.stack([self.xs, self.ys, np.ones_like(self.xs)]).astype(float)  # (3, N)
        self.min_count = max(MIN_OVERLAP * len(self.xs), 1.0)  # pixels two views must share to be compared

    def resized(self, image: np.ndarray) -> np.ndarray:
        """`image` (the sensor's size) at this resolution."""
        return cv2.resize(image, self.size, interpolation=cv2.INTER_AREA)

    def scores(self, sources: list[np.ndarray], images: list[np.ndarray], Rs: np.ndarray) -> np.ndarray:
        """The ZNCC of each image of `images` with the same-index image of `sources` warped by
        each rotation of Rs (C, 3, 3), over the pixels both see: (len(images), C); -1 where
        they share under MIN_OVERLAP or either is flat there."""
        sources = np.stack(sources).astype(np.float32)
        targets = np.stack([im[self.ys, self.xs] for im in images]).astype(np.float32)
        KRs = np.asarray(self.K @ Rs, np.float64)
        return np.concatenate(concurrency.split(
            lambda a, b: _zncc(sources, targets, KRs[a:b], self.bearings, self.seen, self.min_count), len(KRs),
            PARALLEL_CANDIDATES), axis=1)

    def refine(self, source: np.ndarray, image: np.ndarray, Rs: np.ndarray) -> np.ndarray:
        """Each R_source_image of Rs (C, 3, 3) refined by inverse-compositional Gauss-Newton on
        the squared difference of the two views (each normalised to zero mean and unit variance
        over the pixels both see), all at once, up to ALIGN_ITERATIONS steps, stopping once no
        step moves the view by ALIGN_STOP_PX at this resolution."""
        target = image[self.ys, self.xs].astype(float)
        gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)[self.ys, self.xs] / 8
        gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)[self.ys, self.xs] / 8
        X, Y = self.bearings[0], self.bearings[1]  # z = 1
        fx, fy = self.K[0, 0], self.K[1, 1]
        # d image(pi(K exp([d]x) b)) / d d at d = 0 is r (-[b]x), r = grad . d pi / d b
        r0, r1, r2 = gx * fx, gy * fy, -(gx * fx * X + gy * fy * Y)
        J = np.stack([r2 * Y - r1, r0 - r2 * X, r1 * X - r0 * Y], axis=1)  # (N, 3)
        Rs = np.array(Rs, float)
        J, source = np.ascontiguousarray(J), np.asarray(source, np.float32)
        for _ in range(ALIGN_ITERATIONS):
            deltas = _gauss_newton_steps(source, target, J, self.K @ Rs, self.bearings, self.seen, self.min_count)
            Rs = np.array([R @ cv2.Rodrigues(-d)[0] for R, d in zip(Rs, deltas)])
            if np.linalg.norm(deltas, axis=1).max() * fx < ALIGN_STOP_PX:
                break
        return Rs


@numba.njit(cache=True, nogil=True)
def _sample(sources, M, bearings, seen, values, inside):
    """Each image of `sources` (P, h, w) sampled (bilinear) where the homography M puts each
    bearing (3, N): values (P, N) and `inside` (N: ahead of the camera, inside the image and
    where the lens saw, `seen`), written in place; returns how many are inside."""
    P, h, w = sources.shape
    count = 0
    for n in range(bearings.shape[1]):
        bx, by, bz = bearings[0, n], bearings[1, n], bearings[2, n]
        z = M[2, 0] * bx + M[2, 1] * by + M[2, 2] * bz
        inside[n] = False
        if z <= 1e-6:
            continue
        u = (M[0, 0] * bx + M[0, 1] * by + M[0, 2] * bz) / z
        v = (M[1, 0] * bx + M[1, 1] * by + M[1, 2] * bz) / z
        if u < 0 or v < 0 or u > w - 1 or v > h - 1 or not seen[int(v + 0.5), int(u + 0.5)]:
            continue
        i, j = min(int(u), w - 2), min(int(v), h - 2)
        a, b = u - i, v - j
        for p in range(P):
            values[p, n] = ((1 - a) * (1 - b) * sources[p, j, i] + a * (1 - b) * sources[p, j, i + 1]
                            + (1 - a) * b * sources[p, j + 1, i] + a * b * sources[p, j + 1, i + 1])
        inside[n] = True
        count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _gauss_newton_steps(source, target, J, KRs, bearings, seen, min_count):
    """One inverse-compositional Gauss-Newton step (C, 3) for each homography K R_c (C, 3, 3):
    `source` (h, w) sampled where K R_c puts the image view's bearings (3, N), both it and
    `target` (N) normalised to zero mean and unit variance over the pixels both see, `J` (N, 3)
    the target's derivative by the rotation's angles. Zero where under `min_count` pixels are
    shared or either view is flat there."""
    C, N = KRs.shape[0], bearings.shape[1]
    deltas = np.zeros((C, 3))
    values = np.zeros((1, N))
    inside = np.zeros(N, np.bool_)
    sources = source.reshape((1,) + source.shape)
    for c in range(C):
        n = _sample(sources, KRs[c], bearings, seen, values, inside)
        if n < min_count:
            continue
        sv = svv = st = stt = 0.0
        for k in range(N):
            if inside[k]:
                sv += values[0, k]
                svv += values[0, k] * values[0, k]
                st += target[k]
                stt += target[k] * target[k]
        v_mean, t_mean = sv / n, st / n
        v_var, t_var = svv / n - v_mean * v_mean, stt / n - t_mean * t_mean
        if v_var <= 0.0 or t_var <= 0.0:
            continue
        v_std, t_std = np.sqrt(v_var), np.sqrt(t_var)
        H = np.zeros((3, 3))
        g = np.zeros(3)
        for k in range(N):
            if not inside[k]:
                continue
            r = (values[0, k] - v_mean) / v_std - (target[k] - t_mean) / t_std
            for a in range(3):
                g[a] += r * J[k, a]
                for b in range(3):
                    H[a, b] += J[k, a] * J[k, b]
        H /= t_std * t_std
        for a in range(3):
            H[a, a] += 1e-9
        deltas[c] = np.linalg.solve(H, g / t_std)
    return deltas


@numba.njit(cache=True, nogil=True)
def _zncc(sources, targets, KRs, bearings, seen, min_count):
    """scores (P, C): for each image pair p and rotation c, the ZNCC of targets[p] (P, N, at
    the image view's pixels) with sources[p] (P, h, w) sampled (bilinear) where K R_c puts the
    pixels' bearings (3, N), where the source's lens saw (`seen`, h x w); -1 with under
    `min_count` (at least 1) such pixels, or a flat image."""
    P = sources.shape[0]
    C, N = KRs.shape[0], bearings.shape[1]
    out = np.full((P, C), -1.0)
    values = np.zeros((P, N))
    inside = np.zeros(N, np.bool_)
    for c in range(C):
        count = _sample(sources, KRs[c], bearings, seen, values, inside)
        if count < min_count:
            continue
        for p in range(P):
            sx = sy = sxx = syy = sxy = 0.0
            for n in range(N):
                if inside[n]:
                    x, y = values[p, n], targets[p, n]
                    sx += x
                    sy += y
                    sxx += x * x
                    syy += y * y
                    sxy += x * y
            vx, vy = sxx - sx * sx / count, syy - sy * sy / count
            if vx > 0 and vy > 0:
                out[p, c] = (sxy - sx * sy / count) / np.sqrt(vx * vy)
    return out
