"""DAVIS sensor models: APS frames, DVS events (ESIM-style) and an IMU."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from eas_vo.types import EVENT_DTYPE


@dataclass(frozen=True)
class ApsModel:
    """Frame formation: DN = clip(round(Poisson(e) / electrons_per_dn + FPN + read noise - black level)).

    `dn_per_radiance_s`: grey levels per unit radiance per second of exposure. With the
    defaults, radiance ~1 (under a spotlight) gives ~80 DN and the dim ambient light
    (radiance ~0.002-0.02) under 2 DN: an underexposed frame.
    Fixed-pattern noise: a per-pixel and a per-column offset, constant over the sequence.
    The black level is subtracted and clipped at 0, so the darkest parts read as 0.
    """

    exposure_s: float = 0.01
    dn_per_radiance_s: float = 8000.0
    electrons_per_dn: float = 10.0
    read_noise_dn: float = 1.0
    pixel_fpn_dn: float = 0.6
    column_fpn_dn: float = 0.4
    black_level_dn: float = 2.5

    def fixed_pattern(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """The sensor's fixed-pattern offsets [DN], (H, W)."""
        h, w = shape
        return (rng.normal(0, self.pixel_fpn_dn, (h, w)) + rng.normal(0, self.column_fpn_dn, (1, w))).astype(np.float32)

    def expose(self, mean_radiance: np.ndarray, fixed_pattern: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Mean radiance over the exposure (H, W) -> uint8 frame with shot, read and fixed-pattern noise."""
        electrons = mean_radiance * self.exposure_s * self.dn_per_radiance_s * self.electrons_per_dn
        electrons = rng.poisson(np.minimum(electrons, 1e7)).astype(np.float32)
        dn = electrons / self.electrons_per_dn + fixed_pattern + rng.normal(0.0, self.read_noise_dn, electrons.shape)
        dn -= self.black_level_dn
        return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class DvsModel:
    """DVS pixel model: v2e's "noisy" preset (Delbruck, Hu, He, "v2e: From Video Frames to
    Realistic DVS Events", CVPRW 2021; values fixed from it before any APE was looked at).

    Intensity enters as v2e's `inten01` = (luma + 20) / 275 with luma = 255 * min(L /
    white_radiance, 1): the pixel's 8-bit level had the APS imaged it at its default exposure
    (ApsModel: 80 DN per unit radiance, so white_radiance = 255 / 80), the +20 standing for the
    dark current that keeps a black pixel's bandwidth above zero.

    Attributes:
        contrast_threshold: mean log-intensity step per event (v2e noisy: 0.2).
        threshold_sigma: per-pixel mismatch (std) of the ON and OFF thresholds (v2e noisy: 0.05).
        refractory_s: minimum time between two events of a pixel [s] (0.5 ms, as in v0.1).
        log_eps: dark offset in log(radiance + log_eps) [radiance].
        cutoff_hz: photoreceptor 3 dB bandwidth at white [Hz], proportional to inten01 below
            (a first-order low-pass on log intensity; v2e noisy: 30 Hz); 0: unlimited.
        white_radiance: the radiance mapped to full scale (255 / 80, see above).
        shot_noise_rate_hz: shot-noise events per pixel per second in the dark, both polarities
            (v2e noisy: 5 Hz), falling linearly with inten01 to `shot_noise_bright_factor` of it.
        shot_noise_bright_factor: v2e's SHOT_NOISE_INTEN_FACTOR (0.25).
        leak_rate_hz: leak (ON) events per pixel per second (v2e noisy: 0.1 Hz), each pixel's
            rate log-normal with `leak_spread_decades` (v2e: 0.1 decade). v2e lets the leak
            drift the pixel's reference; here they are a Poisson process at that rate.
        hot_pixel_fraction, hot_pixel_rate_hz: pixels that fire at a high rate regardless of
            light (not in v2e: the order of magnitude seen in DAVIS240 recordings).
    """

    contrast_threshold: float = 0.2
    threshold_sigma: float = 0.05
    refractory_s: float = 5e-4
    log_eps: float = 5e-4
    cutoff_hz: float = 30.0
    white_radiance: float = 255.0 / 80.0
    shot_noise_rate_hz: float = 5.0
    shot_noise_bright_factor: float = 0.25
    leak_rate_hz: float = 0.1
    leak_spread_decades: float = 0.1
    hot_pixel_fraction: float = 5e-4
    hot_pixel_rate_hz: float = 500.0

    def inten01(self, radiance: np.ndarray) -> np.ndarray:
        """v2e's normalised intensity of each pixel, (20 / 275) in the dark to 1 at white."""
        return (255.0 * np.minimum(radiance / self.white_radiance, 1.0) + 20.0) / 275.0

    def noise_rate_hz(self, radiance: np.ndarray) -> np.ndarray:
        """Expected shot-noise events per pixel per second at `radiance`, both polarities."""
        return self.shot_noise_rate_hz * ((self.shot_noise_bright_factor - 1.0) * self.inten01(radiance) + 1.0)


@dataclass
class EventTruth:
    """What the simulator knows of its events (for `eas-vo simulate --stats`).

    Attributes:
        noise: per event, True for shot-noise, leak and hot-pixel events.
        latency_s: per event, how long after the unfiltered log intensity crossed the same
            level the event fired [s] (NaN for noise and for events no crossing matched).
        radiance: per event, the pixel's radiance when it fired.
    """

    noise: np.ndarray
    latency_s: np.ndarray
    radiance: np.ndarray


@dataclass(frozen=True)
class StepInput:
    """EventSimulator.prepare's radiance-only part of a step, per pixel (flattened).

    Attributes:
        radiance: the radiance at the step's end.
        log_radiance: log(radiance + log_eps), float32.
        gain: the low-pass filter's gain over the step (None: no filter).
        shot_rate: shot-noise rate [Hz]; noise_rate: shot + leak + hot-pixel rate [Hz];
        noise_cdf: its cumulative sum over the pixels.
    """

    radiance: np.ndarray
    log_radiance: np.ndarray
    gain: np.ndarray | None
    shot_rate: np.ndarray
    noise_rate: np.ndarray
    noise_cdf: np.ndarray


class EventSimulator:
    """Per-pixel threshold crossings of the photoreceptor's low-passed log radiance between
    render steps (as ESIM, the filter as v2e's), timestamps interpolated linearly inside a
    step, threshold mismatch, a refractory period, shot-noise, leak and hot-pixel events.

    Alongside, an unfiltered twin of every pixel records when the raw log radiance crossed
    each level (the last `HISTORY` crossings), so each signal event knows its latency."""

    HISTORY = 8

    def __init__(self, model: DvsModel, shape: tuple[int, int], rng: np.random.Generator):
        self.model = model
        self.shape = shape
        self.rng = rng
        h, w = shape
        n = h * w
        c, s = model.contrast_threshold, model.threshold_sigma
        self.c_pos = np.clip(rng.normal(c, s, n), 0.05, None).astype(np.float32)
        self.c_neg = np.clip(rng.normal(c, s, n), 0.05, None).astype(np.float32)
        self.ref: np.ndarray | None = None
        self.last_lp: np.ndarray | None = None
        self.last_t = np.full(n, -np.inf)
        self.hot_rate = np.zeros(n)
        hot = rng.choice(n, int(round(model.hot_pixel_fraction * n)), replace=False)
        self.hot_rate[hot] = model.hot_pixel_rate_hz * rng.uniform(0.2, 2.0, len(hot))
        self.leak_rate = model.leak_rate_hz * 10.0 ** rng.normal(0.0, model.leak_spread_decades, n)
        # the unfiltered twin: its reference, last log radiance and a ring of (level, time, up)
        self.raw_ref: np.ndarray | None = None
        self.last_raw: np.ndarray | None = None
        self.ring_level = np.full((n, self.HISTORY), np.nan, np.float32)
        self.ring_t = np.full((n, self.HISTORY), np.nan)
        self.ring_up = np.zeros((n, self.HISTORY), bool)
        self.ring_next = np.zeros(n, np.int64)

    def log_intensity(self, radiance: np.ndarray) -> np.ndarray:
        return np.log(radiance.ravel() + self.model.log_eps).astype(np.float32)

    def start(self, radiance: np.ndarray) -> None:
        """Initialise the filter and the reference levels from the first rendered image."""
        self.ref = self.log_intensity(radiance)
        self.last_lp = self.ref.copy()
        self.raw_ref, self.last_raw = self.ref.copy(), self.ref.copy()

    def prepare(self, t0: float, t1: float, radiance: np.ndarray) -> "StepInput":
        """What step (t0, t1] needs of the radiance at t1 alone (no state of the pixels: any
        thread may compute it while the previous step runs)."""
        m = self.model
        flat = radiance.ravel()
        gain = None
        if m.cutoff_hz > 0:  # first-order low-pass, exact for a step held over the interval
            gain = 1.0 - np.exp(-2.0 * np.pi * m.cutoff_hz * m.inten01(flat) * (t1 - t0))
        shot = m.noise_rate_hz(flat)
        rate = shot + self.leak_rate + self.hot_rate
        return StepInput(flat, self.log_intensity(radiance), gain, shot, rate, np.cumsum(rate))

    def step(self, t0: float, t1: float, radiance: "np.ndarray | StepInput") -> tuple[np.ndarray, EventTruth]:
        """Events in (t0, t1] given the radiance at t1 (or its prepare()), sorted by time, and their truth."""
        given = radiance if isinstance(radiance, StepInput) else self.prepare(t0, t1, radiance)
        flat, raw1 = given.radiance, given.log_radiance
        lp1 = raw1 if given.gain is None else (self.last_lp + given.gain * (raw1 - self.last_lp)).astype(np.float32)
        self._record_raw_crossings(t0, t1, raw1)
        signal, levels = self._crossings(t0, t1, self.last_lp, lp1)
        self.last_lp = lp1
        latency = self._latency(signal, levels)
        noise = self._noise(t0, t1, given)
        events = np.concatenate([signal, noise])
        truth = EventTruth(
            np.concatenate([np.zeros(len(signal), bool), np.ones(len(noise), bool)]),
            np.concatenate([latency, np.full(len(noise), np.nan)]),
            flat[events["y"].astype(np.int64) * self.shape[1] + events["x"]],
        )
        order = np.argsort(events["t"], kind="stable")
        return events[order], EventTruth(truth.noise[order], truth.latency_s[order], truth.radiance[order])

    def _levels_crossed(self, ref, v1):
        """Crossings of the thresholds around `ref` on the way to v1: counts up and down."""
        n_pos, n_neg = np.empty(len(ref), np.int64), np.empty(len(ref), np.int64)
        _count_levels(ref, v1, self.c_pos, self.c_neg, n_pos, n_neg)
        return n_pos, n_neg

    def _record_raw_crossings(self, t0, t1, raw1) -> None:
        n_pos, n_neg = self._levels_crossed(self.raw_ref, raw1)
        _record_crossings(
            t0,
            t1,
            self.raw_ref,
            self.last_raw,
            raw1,
            n_pos,
            n_neg,
            self.c_pos,
            self.c_neg,
            self.ring_level,
            self.ring_t,
            self.ring_up,
            self.ring_next,
        )
        self.last_raw = raw1

    def _crossings(self, t0, t1, v0, v1) -> tuple[np.ndarray, np.ndarray]:
        """Signal events of the filtered signal from v0 to v1 and the levels they crossed, in
        the order of the k-th crossings of all pixels (k = 1, 2, ...), pixels in index order."""
        w = self.shape[1]
        n_pos, n_neg = self._levels_crossed(self.ref, v1)
        total = int((n_pos + n_neg).sum())
        pix, t, up, level, k = (
            np.empty(total, dtype) for dtype in (np.int64, np.float64, np.bool_, np.float32, np.int64)
        )
        kept = _signal_crossings(
            t0,
            t1,
            self.ref,
            v0,
            v1,
            n_pos,
            n_neg,
            self.c_pos,
            self.c_neg,
            self.last_t,
            self.model.refractory_s,
            pix,
            t,
            up,
            level,
            k,
        )
        order = np.argsort(k[:kept], kind="stable")  # pixel-major -> crossing-major, pixels still in order
        pix, level = pix[order], level[order]
        ev = np.empty(kept, EVENT_DTYPE)
        ev["t"], ev["x"], ev["y"], ev["p"] = t[order], pix % w, pix // w, up[order]
        return ev, level

    def _latency(self, events: np.ndarray, levels: np.ndarray) -> np.ndarray:
        """Each event's time minus the latest earlier unfiltered crossing in its pixel of the
        same direction and level (within half a threshold: the two references may have
        drifted apart by unequal ON and OFF steps); NaN when none of the last HISTORY matches."""
        pix = events["y"].astype(np.int64) * self.shape[1] + events["x"]
        tolerance = 0.5 * np.minimum(self.c_pos[pix], self.c_neg[pix])[:, None]
        match = (np.abs(self.ring_level[pix] - levels[:, None]) < tolerance) & (
            self.ring_up[pix] == events["p"][:, None].astype(bool)
        )
        t_raw = np.where(match & (self.ring_t[pix] <= events["t"][:, None]), self.ring_t[pix], -np.inf).max(axis=1)
        return np.where(np.isfinite(t_raw), events["t"] - t_raw, np.nan)

    def _noise(self, t0, t1, given: "StepInput") -> np.ndarray:
        """Shot-noise (either polarity), leak (ON) and hot-pixel events in (t0, t1]."""
        rate, cdf = given.noise_rate, given.noise_cdf
        count = self.rng.poisson(cdf[-1] * (t1 - t0))
        pix = np.searchsorted(cdf, self.rng.uniform(0, cdf[-1], count))
        ev = np.empty(count, EVENT_DTYPE)
        ev["t"] = self.rng.uniform(t0, t1, count)
        ev["x"], ev["y"] = pix % self.shape[1], pix // self.shape[1]
        shot = given.shot_rate[pix]
        on_share = (0.5 * shot + self.leak_rate[pix] + 0.5 * self.hot_rate[pix]) / rate[pix]
        ev["p"] = self.rng.random(count) < on_share
        return ev


@dataclass(frozen=True)
class ImuModel:
    """Continuous-time white-noise densities and bias scales (MPU-6150-like, as on the DAVIS)."""

    gyro_noise: float = 0.003  # rad/s/sqrt(Hz)
    acc_noise: float = 0.02  # m/s^2/sqrt(Hz)
    gyro_bias: float = 0.01  # rad/s, std of the constant bias
    acc_bias: float = 0.05  # m/s^2
    gravity_w: tuple = (0.0, 9.81, 0.0)  # world y points down

    def measure(self, R_w_c, omega_c, acc_w, rate_hz: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Accelerometer (specific force) and gyro readings in the camera frame, with bias and
        noise, for readings taken at `rate_hz` [Hz] (the discrete noise std is density * sqrt(rate))."""
        n = len(omega_c)
        sqrt_rate = np.sqrt(rate_hz)
        gyro = omega_c + rng.normal(0, self.gyro_bias, 3) + rng.normal(0, self.gyro_noise * sqrt_rate, (n, 3))
        specific_w = acc_w - np.asarray(self.gravity_w)
        acc = np.einsum("nji,nj->ni", R_w_c, specific_w)
        acc += rng.normal(0, self.acc_bias, 3) + rng.normal(0, self.acc_noise * sqrt_rate, (n, 3))
        return acc, gyro


# -- compiled crossing loops: each pixel's crossings in order, in float32 as numpy computes them --


@numba.njit(cache=True, nogil=True, inline="always")
def _crossing(t0, t1, ref, v0, span, step, k):
    """The k-th level crossed from v0 (span: v1 - v0, 1e-12 if 0) and its time [s]: the level
    ref + k * step in float32, its time linear between t0 and t1 (float64)."""
    level = ref + np.float32(k) * step
    frac = (level - v0) / span
    if frac < np.float32(0.0):
        frac = np.float32(0.0)
    elif frac > np.float32(1.0):
        frac = np.float32(1.0)
    return level, t0 + np.float64(frac) * (t1 - t0)


@numba.njit(cache=True, nogil=True, inline="always")
def _pixel_run(ref, v0, v1, n_pos, n_neg, c_pos, c_neg, p):
    """(crossings, direction, step, span) of pixel p."""
    up = n_pos[p] > 0
    step = c_pos[p] if up else -c_neg[p]
    span = v1[p] - v0[p]
    if span == 0:
        span = np.float32(1e-12)
    return n_pos[p] + n_neg[p], up, step, span


@numba.njit(cache=True, nogil=True)
def _count_levels(ref, v1, c_pos, c_neg, n_pos, n_neg):
    """Per pixel, the thresholds around ref crossed on the way to v1, up and down, as numpy
    computes floor(max(+-(v1 - ref), 0) / c) in float32 (exact operations: the same bits)."""
    for p in range(len(ref)):
        diff = v1[p] - ref[p]
        n_pos[p] = np.int64(np.floor(max(diff, np.float32(0.0)) / c_pos[p]))
        n_neg[p] = np.int64(np.floor(max(-diff, np.float32(0.0)) / c_neg[p]))


@numba.njit(cache=True, nogil=True, inline="always")
def _advance(ref, n_pos, n_neg, c_pos, c_neg, p):
    """Pixel p's reference moved by the levels it crossed, as numpy's float32 `ref += n_pos *
    c_pos - n_neg * c_neg` computes it (in float64, rounded to float32)."""
    ref[p] = np.float32(
        np.float64(ref[p]) + (np.float64(n_pos[p]) * np.float64(c_pos[p]) - np.float64(n_neg[p]) * np.float64(c_neg[p]))
    )


@numba.njit(cache=True, nogil=True)
def _record_crossings(t0, t1, ref, v0, v1, n_pos, n_neg, c_pos, c_neg, ring_level, ring_t, ring_up, ring_next):
    """Each pixel's crossings from v0 to v1 into its ring of the last crossings (level, time,
    direction); its reference `ref` moved past them."""
    history = ring_level.shape[1]
    for p in range(len(ref)):
        if n_pos[p] + n_neg[p] == 0:
            continue
        n, up, step, span = _pixel_run(ref, v0, v1, n_pos, n_neg, c_pos, c_neg, p)
        for k in range(1, n + 1):
            level, t = _crossing(t0, t1, ref[p], v0[p], span, step, k)
            slot = ring_next[p] % history
            ring_level[p, slot], ring_t[p, slot], ring_up[p, slot] = level, t, up
            ring_next[p] += 1
        _advance(ref, n_pos, n_neg, c_pos, c_neg, p)


@numba.njit(cache=True, nogil=True)
def _signal_crossings(t0, t1, ref, v0, v1, n_pos, n_neg, c_pos, c_neg, last_t, refractory_s, pix, t, up, level, k):
    """Each pixel's crossings from v0 to v1 that come at least `refractory_s` after its last
    event, pixel by pixel (pixel, time, direction, level, crossing number); returns their count.
    Each pixel's reference `ref` is moved past all its crossings, kept or not."""
    kept = 0
    for p in range(len(ref)):
        if n_pos[p] + n_neg[p] == 0:
            continue
        n, direction, step, span = _pixel_run(ref, v0, v1, n_pos, n_neg, c_pos, c_neg, p)
        for j in range(1, n + 1):
            lv, tj = _crossing(t0, t1, ref[p], v0[p], span, step, j)
            if tj - last_t[p] >= refractory_s:
                last_t[p] = tj
                pix[kept], t[kept], up[kept], level[kept], k[kept] = p, tj, direction, lv, j
                kept += 1
        _advance(ref, n_pos, n_neg, c_pos, c_neg, p)
    return kept
