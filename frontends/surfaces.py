"""Time surfaces: TS (Lagorce et al., HOTS, TPAMI 2017) and SITS, the speed-invariant
time surface (Manderscheid et al., CVPR 2019). Both consume the event stream
incrementally (each sample adds the events since the previous one) and render the
surface at the sample time."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np

from eas_vo.plugins import Frontend
from eas_vo.types import EVENT_DTYPE, Sample
from eas_vo.validation import check_choice, check_range

POLARITY_MODES = ("merged", "split")


def _channels(events: np.ndarray, split: bool) -> np.ndarray:
    """Surface channel per event: 0, or the polarity (0 OFF, 1 ON) when polarities are split."""
    return np.ascontiguousarray(events["p"], dtype=np.int32) if split else np.zeros(len(events), np.int32)


class _SurfaceFrontend(Frontend):
    """A surface updated by the events since the previous sample, then rendered at its time."""

    needs_events = True
    shows_the_past = True

    def __init__(self, config=None, camera=None):
        super().__init__(config, camera)
        self.reset()

    def consume(self, events: np.ndarray) -> None:
        raise NotImplementedError

    def render(self, t_s: float) -> np.ndarray:
        raise NotImplementedError

    def __call__(self, sample: Sample) -> np.ndarray:
        self.consume(sample.events_since_previous)
        return self.render(sample.t)


# ----------------------------------------------------------------------------- TS


@numba.njit(cache=True, nogil=True)
def update_latest_times(latest, t, x, y, channel):
    """TS state: latest[channel, y, x] = t for each event, in order."""
    for i in range(len(t)):
        latest[channel[i], y[i], x[i]] = t[i]


def time_surface(latest: np.ndarray, t_s: float, tau_s: float) -> np.ndarray:
    """exp(-(t_s - T) / tau) per pixel and channel; 0 where no event was seen (T = -inf)."""
    return np.exp(-(t_s - latest) / tau_s)


@dataclass(frozen=True)
class TsConfig:
    """tau_s: decay constant [s]; polarity: `merged` (the paper ignores it) or `split`
    (ON and OFF surfaces, rendered as 128 + 127.5 * (ON - OFF))."""

    tau_s: float = 0.03
    polarity: str = "merged"

    def validate(self) -> None:
        check_range(self, "tau_s", 0.0, 1e3, lo_open=True)
        check_choice(self, "polarity", POLARITY_MODES)


class TsFrontend(_SurfaceFrontend):
    """Time surface: per pixel the latest event time, decayed exponentially to the sample time."""

    name = "ts"
    description = "time surface (HOTS): exp(-(t - T_last(x, y)) / tau), rendered at the sample time"
    Config = TsConfig

    def reset(self) -> None:
        channels = 2 if self.config.polarity == "split" else 1
        self.latest = np.full((channels, self.camera.height, self.camera.width), -np.inf)

    def consume(self, events: np.ndarray) -> None:
        split = self.config.polarity == "split"
        update_latest_times(
            self.latest,
            np.ascontiguousarray(events["t"]),
            np.ascontiguousarray(events["x"]),
            np.ascontiguousarray(events["y"]),
            _channels(events, split),
        )

    def render(self, t_s: float) -> np.ndarray:
        surface = time_surface(self.latest, t_s, self.config.tau_s)
        if len(surface) == 2:
            image = 127.5 + 127.5 * (surface[1] - surface[0])
        else:
            image = 255.0 * surface[0]
        return np.clip(np.rint(image), 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------- SITS


@functools.cache
def sits_kernel(r: int):
    """The SITS update for radius `r`, compiled with r as a constant so that the window loops
    unroll and vectorise (compiled on first use per radius and process).

    kernel(surface, records, split, dv_compatible), `records` the events' packed EVENT_DTYPE
    bytes (read in place, no field copies): for each event in order, in the (2r+1)^2
    neighbourhood every value greater than the centre's is decremented, then the centre is
    set to (2r+1)^2. With `dv_compatible`, the neighbourhood is dv-processing's: (2r)^2 pixels
    from (x-r, y-r) to (x+r-1, y+r-1) when that lies strictly inside the sensor, else the
    clipped (2r+1)^2 one (as its bounds-checked path does).
    """
    side = 2 * r + 1
    full = side * side

    @numba.njit(nogil=True, error_model="numpy")
    def kernel(surface, records, split, dv_compatible):
        height, width = surface.shape[1], surface.shape[2]
        flat = surface.reshape(-1)
        for e in range(0, len(records), 13):
            cx = np.int64(records[e + 8]) | (np.int64(records[e + 9]) << 8)
            cy = np.int64(records[e + 10]) | (np.int64(records[e + 11]) << 8)
            base = (records[e + 12] > 0) * height * width if split else 0
            centre = flat[base + cy * width + cx]
            inside = cx - r > 0 and cy - r > 0 and cx + r < width and cy + r < height
            # Unsigned indices spare numba's negative-index checks; constant trip counts let
            # the window loops unroll and vectorise.
            if inside and dv_compatible:
                o = np.uint64(base + (cy - r) * width + cx - r)
                for _ in range(side - 1):
                    for xx in range(np.uint64(side - 1)):
                        v = flat[o + xx]
                        flat[o + xx] = v - (v > centre)
                    o += np.uint64(width)
            elif inside:
                o = np.uint64(base + (cy - r) * width + cx - r)
                for _ in range(side):
                    for xx in range(np.uint64(side)):
                        v = flat[o + xx]
                        flat[o + xx] = v - (v > centre)
                    o += np.uint64(width)
            else:
                x0, x1 = max(cx - r, 0), min(cx + r, width - 1)
                for yy in range(max(cy - r, 0), min(cy + r, height - 1) + 1):
                    o = base + yy * width
                    for xx in range(o + x0, o + x1 + 1):
                        v = flat[xx]
                        flat[xx] = v - (v > centre)
            flat[base + cy * width + cx] = full

    return kernel


@dataclass(frozen=True)
class SitsConfig:
    """r: neighbourhood radius [px]; polarity: `merged` (rendered min-max normalised, as
    dv-processing does) or `split` (per-polarity surfaces, rendered as
    128 + 127.5 * (ON - OFF) / (2r+1)^2); dv_compatible: dv-processing's window."""

    r: int = 4
    polarity: str = "merged"
    dv_compatible: bool = False

    def validate(self) -> None:
        check_range(self, "r", 1, 50)
        check_choice(self, "polarity", POLARITY_MODES)


class SitsFrontend(_SurfaceFrontend):
    """Speed-invariant time surface, updated event by event and rendered at the sample time."""

    name = "sits"
    description = "speed-invariant time surface (Manderscheid et al. 2019), updated event by event"
    Config = SitsConfig

    def reset(self) -> None:
        channels = 2 if self.config.polarity == "split" else 1
        dtype = np.uint8 if (2 * self.config.r + 1) ** 2 <= 255 else np.int32  # narrow: faster
        self.surface = np.zeros((channels, self.camera.height, self.camera.width), dtype)

    def consume(self, events: np.ndarray) -> None:
        c = self.config
        records = np.ascontiguousarray(events, dtype=EVENT_DTYPE).view(np.uint8)
        sits_kernel(c.r)(self.surface, records, c.polarity == "split", c.dv_compatible)

    def render(self, t_s: float = 0.0) -> np.ndarray:
        """The surface as uint8 (SITS holds no time: `t_s` is unused)."""
        full = (2 * self.config.r + 1) ** 2
        if len(self.surface) == 2:
            image = 127.5 + 127.5 * (self.surface[1].astype(float) - self.surface[0]) / full
            return np.clip(np.rint(image), 0, 255).astype(np.uint8)
        # Min-max normalisation, exactly as dv-processing renders its frames.
        values = self.surface[0].astype(np.int64)
        lo, hi = values.min(), values.max()
        return ((values - lo) * 255 // max(hi - lo, 1)).astype(np.uint8)
