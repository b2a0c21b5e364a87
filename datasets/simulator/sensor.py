"""DAVIS sensor models: APS frames, DVS events (ESIM-style) and an IMU."""

from __future__ import annotations

from dataclasses import dataclass

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
    """Event generation parameters.

    Attributes:
        contrast_threshold: mean log-intensity step per event.
        threshold_sigma: per-pixel mismatch (std) of the thresholds.
        refractory_s: minimum time between two events of a pixel [s].
        log_eps: dark-current offset in log(radiance + log_eps).
        noise_rate_hz: background activity per pixel in bright light [Hz].
        dark_noise_rate_hz: extra background activity in the dark [Hz] (falls off above `dark_radiance`).
        dark_radiance: radiance below which the dark noise dominates.
        hot_pixel_fraction, hot_pixel_rate_hz: a few pixels that fire at a high rate regardless of light.
    """

    contrast_threshold: float = 0.3
    threshold_sigma: float = 0.03
    refractory_s: float = 5e-4
    log_eps: float = 5e-4
    noise_rate_hz: float = 0.05
    dark_noise_rate_hz: float = 2.0
    dark_radiance: float = 0.01
    hot_pixel_fraction: float = 5e-4
    hot_pixel_rate_hz: float = 500.0


class EventSimulator:
    """Per-pixel log-radiance threshold crossings between render steps (as ESIM), with
    timestamps interpolated linearly inside a step, threshold mismatch, a refractory
    period and background-activity noise that grows in the dark."""

    def __init__(self, model: DvsModel, shape: tuple[int, int], rng: np.random.Generator):
        self.model = model
        self.shape = shape
        self.rng = rng
        h, w = shape
        c, s = model.contrast_threshold, model.threshold_sigma
        self.c_pos = np.clip(rng.normal(c, s, h * w), 0.05, None).astype(np.float32)
        self.c_neg = np.clip(rng.normal(c, s, h * w), 0.05, None).astype(np.float32)
        self.ref: np.ndarray | None = None
        self.last_log: np.ndarray | None = None
        self.last_t = np.full(h * w, -np.inf)
        self.hot_rate = np.zeros(h * w)
        hot = rng.choice(h * w, int(round(model.hot_pixel_fraction * h * w)), replace=False)
        self.hot_rate[hot] = model.hot_pixel_rate_hz * rng.uniform(0.2, 2.0, len(hot))

    def log_intensity(self, radiance: np.ndarray) -> np.ndarray:
        return np.log(radiance.ravel() + self.model.log_eps).astype(np.float32)

    def start(self, radiance: np.ndarray) -> None:
        """Initialise the reference levels from the first rendered image."""
        self.ref = self.log_intensity(radiance)
        self.last_log = self.ref.copy()

    def step(self, t0: float, t1: float, radiance: np.ndarray) -> np.ndarray:
        """Events in (t0, t1] given the radiance at t1; returns EVENT_DTYPE sorted by time."""
        log1 = self.log_intensity(radiance)
        log0 = self.last_log
        diff = log1 - self.ref
        n_pos = np.floor(np.maximum(diff, 0) / self.c_pos).astype(np.int64)
        n_neg = np.floor(np.maximum(-diff, 0) / self.c_neg).astype(np.int64)
        signal = self._crossings(t0, t1, log0, log1, n_pos, n_neg)
        self.ref += n_pos * self.c_pos - n_neg * self.c_neg
        self.last_log = log1
        noise = self._noise(t0, t1, radiance.ravel())
        events = np.concatenate([signal, noise])
        return events[np.argsort(events["t"], kind="stable")]

    def _crossings(self, t0, t1, log0, log1, n_pos, n_neg) -> np.ndarray:
        w = self.shape[1]
        n_cross = n_pos + n_neg
        out = []
        for k in range(1, int(n_cross.max(initial=0)) + 1):
            pix = np.flatnonzero(n_cross >= k)
            positive = n_pos[pix] > 0
            step = np.where(positive, self.c_pos[pix], -self.c_neg[pix])
            level = self.ref[pix] + k * step
            span = log1[pix] - log0[pix]
            frac = np.clip((level - log0[pix]) / np.where(span == 0, 1e-12, span), 0.0, 1.0)
            t = t0 + frac.astype(np.float64) * (t1 - t0)  # float64: a float32 time would be us-coarse
            keep = t - self.last_t[pix] >= self.model.refractory_s
            pix, t, positive = pix[keep], t[keep], positive[keep]
            self.last_t[pix] = t
            ev = np.empty(len(pix), EVENT_DTYPE)
            ev["t"], ev["x"], ev["y"], ev["p"] = t, pix % w, pix // w, positive
            out.append(ev)
        return np.concatenate(out) if out else np.empty(0, EVENT_DTYPE)

    def _noise(self, t0, t1, radiance) -> np.ndarray:
        m = self.model
        rate = m.noise_rate_hz + m.dark_noise_rate_hz / (1.0 + radiance / m.dark_radiance) + self.hot_rate
        cdf = np.cumsum(rate)
        count = self.rng.poisson(cdf[-1] * (t1 - t0))
        pix = np.searchsorted(cdf, self.rng.uniform(0, cdf[-1], count))
        ev = np.empty(count, EVENT_DTYPE)
        ev["t"] = self.rng.uniform(t0, t1, count)
        ev["x"], ev["y"] = pix % self.shape[1], pix // self.shape[1]
        ev["p"] = self.rng.integers(0, 2, count)
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
