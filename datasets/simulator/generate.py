"""Generate a synthetic sequence and write it in the Event Camera Dataset text layout."""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.datasets.simulator.motion import HandHeldMotion
from eas_vo.datasets.simulator.scene import Scene
from eas_vo.datasets.simulator.sensor import ApsModel, DvsModel, EventSimulator, ImuModel
from eas_vo.geometry.rotations import quats_from_matrices
from eas_vo.types import EVENT_DTYPE, ImuSeries, PoseSeries
from eas_vo.validation import check_range

SIMULATOR_VERSION = 3  # bump when the output for a given config changes (invalidates caches)


@dataclass(frozen=True)
class SimCamera:
    """The simulated camera: sensor size [px], pinhole intrinsics [px] and its lens, a model of
    LENS_MODELS with its coefficients (in that model's order). The default is the DAVIS240
    (240x180) with the radial-tangential lens every earlier sequence had."""

    width: int = 240
    height: int = 180
    fx: float = 200.0
    fy: float = 200.0
    cx: float = 121.5
    cy: float = 89.0
    lens: str = "radtan"
    dist: tuple = (-0.25, 0.08, 0.0002, -0.0003, 0.0)

    def model(self) -> CameraModel:
        K = np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])
        return CameraModel(self.width, self.height, K, np.array(self.dist, dtype=float), self.lens)

    def resized(self, width: int, height: int) -> "SimCamera":
        """This camera with a width x height sensor [px]: the same diagonal field of view (focal
        lengths scaled with the diagonal), the principal point at the same relative place, the
        same lens (its coefficients act on normalised coordinates or angles, not pixels)."""
        if (width, height) == (self.width, self.height):
            return self
        scale = math.hypot(width, height) / math.hypot(self.width, self.height)
        return dataclasses.replace(
            self,
            width=width,
            height=height,
            fx=self.fx * scale,
            fy=self.fy * scale,
            cx=(self.cx + 0.5) * width / self.width - 0.5,
            cy=(self.cy + 0.5) * height / self.height - 0.5,
        )


#: Sensors the simulator has a preset for: size and a typical calibration.
#: davis240: the simulator's DAVIS240 (240x180), near the Event Camera Dataset's DAVIS240C
#: calibration (fx 199 px, k1 -0.37).
#: davis346: the DAVIS346 (346x260, 18.5 um pixels: iniVation's datasheet) as calibrated in MVSEC
#: (Zhu et al., RA-L 2018), the left camera of its indoor_flying kalibr camchain: pinhole with an
#: equidistant lens, 118 deg across the diagonal (the davis240: 82).
SENSORS = {
    "davis240": SimCamera(),
    "davis346": SimCamera(
        346,
        260,
        226.38018519795807,
        226.15002947047415,
        173.6470807871759,
        133.73271487507847,
        "equidistant",
        (-0.048031442223833355, 0.011330957517194437, -0.055378166304281135, 0.021500973881459395),
    ),
}
DAVIS240_CAMERA = SENSORS["davis240"].model()


@dataclass(frozen=True)
class SimConfig:
    """A synthetic sequence.

    Attributes:
        duration_s: length [s]; seed: makes everything deterministic.
        frame_rate_hz: APS frame rate; gt_rate_hz: ground-truth and IMU rate.
        max_flow_px: largest image motion between two render steps [px] (ESIM's adaptive step).
        speed_growth: the motion's speed grows by the factor (1 + speed_growth) over the sequence.
        speed: the motion's speed scale: 1 is the hand-held default; the same path and scene,
            travelled faster (docs/synthetic.md, "Simulating other sequences", gives the
            speeds).
        translation_scale: the motion's translation scale (1: the hand-held default, 4-5 cm
            amplitude per axis; 5: a hand-held walk's tens of cm); the same path, its positions
            scaled, the rotation unchanged.
        exposure_samples: renders averaged over a frame's exposure at speed 1 (motion blur);
            `speed` times as many at other speeds, so each sample moves as far as at speed 1.
        illumination: scale of the scene's light (1.0: the default dim room); the APS and the
            DVS see radiance times this.
    """

    duration_s: float = 10.0
    seed: int = 0
    illumination: float = 1.0
    frame_rate_hz: float = 20.0
    gt_rate_hz: float = 200.0
    max_flow_px: float = 0.5
    speed_growth: float = 1.5
    speed: float = 1.0
    translation_scale: float = 1.0
    exposure_samples: int = 8
    aps: ApsModel = field(default_factory=ApsModel)
    dvs: DvsModel = field(default_factory=DvsModel)
    imu: ImuModel = field(default_factory=ImuModel)
    camera: SimCamera = field(default_factory=SimCamera)

    def validate(self) -> None:
        check_range(self, "duration_s", 0.2, 3600.0)
        check_range(self, "seed", 0, 2**63 - 1)
        check_range(self, "frame_rate_hz", 1.0, 1000.0)
        check_range(self, "illumination", 0.0, 1e6, lo_open=True)
        check_range(self, "speed", 0.0, 20.0, lo_open=True)
        check_range(self, "translation_scale", 0.0, 100.0)

    def fingerprint(self) -> str:
        """The simulator version and every value, float fields as floats (speed=4 and 4.0 are
        one sequence); the default camera and translation scale left out, so that sequences
        simulated before they could change keep their key (their output is the same)."""
        values = _as_typed_dict(self)
        if self.camera == SimCamera():
            del values["camera"]
        if self.translation_scale == 1.0:
            del values["translation_scale"]
        return repr((SIMULATOR_VERSION, values))


def _as_typed_dict(config) -> dict:
    """dataclasses.asdict, with the values of fields annotated `float` converted to float."""
    return {
        f.name: _as_typed_dict(v) if dataclasses.is_dataclass(v) else float(v) if f.type == "float" else v
        for f in dataclasses.fields(config)
        for v in [getattr(config, f.name)]
    }


def camera_rays(camera: CameraModel) -> np.ndarray:
    """Unit-depth ray (x, y, 1) in the camera frame for every pixel centre, (H*W, 3) float32."""
    return camera.pixel_rays.astype(np.float32)


@dataclass(frozen=True)
class SimStats:
    """What the simulator knows about the events it wrote (its own ground truth).

    Dark pixels see under 2.5 % of the DVS model's white radiance, bright ones over 10 %
    (`dark_pixel_s`, `bright_pixel_s`: pixel-seconds spent so). Rates are per pixel [Hz];
    latencies [s] are medians over the signal events whose unfiltered crossing was found
    (`latency_matched` of them)."""

    duration_s: float
    events: int
    noise_fraction: float
    noise_rate_dark_hz: float
    noise_rate_bright_hz: float
    latency_dark_s: float
    latency_bright_s: float
    latency_matched: float
    dark_pixel_s: float
    bright_pixel_s: float

    def lines(self) -> list[str]:
        def ms(s):
            return "-" if s != s else f"{1e3 * s:.1f} ms"

        def hz(rate, pixel_s):
            return f"{rate:.2f} Hz" if pixel_s else "- (no such pixels)"

        return [
            f"events: {self.events:,} ({self.events / self.duration_s / 1e6:.2f} M events/s), noise fraction {self.noise_fraction:.3f}",
            f"noise rate per pixel: dark {hz(self.noise_rate_dark_hz, self.dark_pixel_s)}, "
            f"bright {hz(self.noise_rate_bright_hz, self.bright_pixel_s)}",
            f"median event latency after the unfiltered crossing: dark {ms(self.latency_dark_s)}, "
            f"bright {ms(self.latency_bright_s)} ({100 * self.latency_matched:.0f} % of signal events matched)",
        ]


DARK, BRIGHT = 0.025, 0.1  # fractions of the DVS white radiance splitting dark and bright pixels


def simulate(config: SimConfig, out_dir: str | Path, progress: bool = False) -> SimStats:
    """Simulate `config`, write the sequence into `out_dir` (ECD layout) and return its stats."""
    from eas_vo.datasets.ecd import write_ecd_folder

    scene_rng, motion_rng, dvs_rng, aps_rng, imu_rng = _generators(config)
    camera = config.camera.model()
    shape = (camera.height, camera.width)
    motion = HandHeldMotion(motion_rng, config.duration_s, config.speed_growth, config.speed, config.translation_scale)
    render = _renderer(config, camera, motion, scene_rng)
    frame_times = np.arange(
        config.aps.exposure_s, config.duration_s - config.aps.exposure_s, 1.0 / config.frame_rate_hz
    )
    samples = max(1, math.ceil(config.exposure_samples * config.speed))
    offsets = (np.arange(samples) + 0.5) / samples - 0.5

    def exposure(t: float) -> np.ndarray:
        """The radiance averaged over the frame exposure centred on t (motion blur)."""
        return np.mean([render(t + dt * config.aps.exposure_s) for dt in offsets], axis=0)

    steps = _render_steps(config, camera, motion)
    sim = EventSimulator(config.dvs, shape, dvs_rng)
    rendered = _rendered_ahead(
        _event_inputs(sim, render, steps) + [functools.partial(exposure, t) for t in frame_times]
    )
    events, stats = _simulate_events(config, sim, steps, rendered, progress)
    fixed_pattern = config.aps.fixed_pattern(shape, aps_rng)
    frames = [config.aps.expose(next(rendered), fixed_pattern, aps_rng) for _ in frame_times]

    gt_t = np.arange(0.0, config.duration_s, 1.0 / config.gt_rate_hz)
    R_w_c, p_w_c = motion.pose(gt_t)
    ground_truth = PoseSeries(gt_t, p_w_c, quats_from_matrices(R_w_c))
    acc, gyro = config.imu.measure(
        R_w_c, motion.angular_velocity(gt_t), motion.acceleration(gt_t), config.gt_rate_hz, imu_rng
    )
    write_ecd_folder(out_dir, camera, frame_times, frames, events, ground_truth, ImuSeries(gt_t, acc, gyro))
    return stats


def simulate_events(config: SimConfig, motion) -> tuple[np.ndarray, SimStats]:
    """The events (EVENT_DTYPE) and their stats of `config`'s scene, camera and DVS over
    config.duration_s, the camera moving along `motion` (pose(t), angular_velocity(t) as
    HandHeldMotion's, e.g. motion.ConstantMotion) instead of the hand-held path."""
    scene_rng, _, dvs_rng, _, _ = _generators(config)
    camera = config.camera.model()
    render = _renderer(config, camera, motion, scene_rng)
    steps = _render_steps(config, camera, motion)
    sim = EventSimulator(config.dvs, (camera.height, camera.width), dvs_rng)
    return _simulate_events(config, sim, steps, (job() for job in _event_inputs(sim, render, steps)), False)


def _generators(config: SimConfig) -> tuple[np.random.Generator, ...]:
    """The scene's, motion's, DVS's, APS's and IMU's generators, from config.seed."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(config.seed).spawn(5))


def _renderer(config: SimConfig, camera: CameraModel, motion, scene_rng: np.random.Generator):
    """t [s] -> the radiance every pixel sees then (H, W), the scene built from scene_rng."""
    scene = Scene(scene_rng)
    rays = camera_rays(camera)
    shape = (camera.height, camera.width)

    def render(t: float) -> np.ndarray:
        R, p = motion.pose(t)
        return scene.render(R[0], p[0], rays, shape) * np.float32(config.illumination)

    return render


def _render_steps(config, camera, motion) -> list[float]:
    """The times [s] the scene is rendered at for the events: 0, then adaptive steps (the
    largest image motion in a step `max_flow_px`, ESIM's rule) up to the duration."""
    max_ray = math.hypot(camera.width, camera.height) / (2 * camera.focal_px)
    t, steps = 0.0, [0.0]
    while t < config.duration_s:
        omega = float(np.linalg.norm(motion.angular_velocity([t])[0]))
        flow_rate = camera.focal_px * omega * (1 + max_ray**2) + 1e-6  # px/s at the image corner
        t = min(t + float(np.clip(config.max_flow_px / flow_rate, 2e-4, 5e-3)), config.duration_s)
        steps.append(t)
    return steps


def _event_inputs(sim: EventSimulator, render, steps: list[float]) -> list:
    """Jobs giving what the sensor takes, in order: the radiance at steps[0], then per step
    the radiance at its end with the sensor's radiance-only work done (EventSimulator.prepare)."""
    return [functools.partial(render, steps[0])] + [
        functools.partial(_prepared, sim, render, t0, t1) for t0, t1 in zip(steps, steps[1:])
    ]


def _prepared(sim: EventSimulator, render, t0: float, t1: float):
    return sim.prepare(t0, t1, render(t1))


def _rendered_ahead(jobs: list, depth: int = 4):
    """Each job's result, in order, computed on two worker threads up to `depth` jobs ahead:
    the ray casts (compiled, one thread each, without the GIL) and the sensor's radiance-only
    work run while the sensor model works on the previous step, and the frames' exposures two
    at a time. The same results as computed in turn."""
    with ThreadPoolExecutor(2, initializer=numba.set_num_threads, initargs=(1,)) as worker:
        pending = collections.deque(worker.submit(job) for job in jobs[:depth])
        for job in jobs[depth:]:
            yield pending.popleft().result()
            pending.append(worker.submit(job))
        while pending:
            yield pending.popleft().result()


def _simulate_events(config, sim: EventSimulator, steps, inputs, progress) -> tuple[np.ndarray, SimStats]:
    """Events between consecutive render steps (`steps` [s]; `inputs` as _event_inputs gives)."""
    from tqdm import tqdm

    sim.start(next(inputs))
    chunks, truths = [], []
    pixel_s = np.zeros(2)  # dark, bright
    white = config.dvs.white_radiance
    # simulated time counted in whole microseconds, so that the bar ends exactly at its total
    # (a sum of float steps passes it: tqdm warns), and shown in seconds
    with tqdm(
        total=round(config.duration_s * 1e6),
        unit_scale=1e-6,
        disable=not progress,
        desc="simulating events",
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} s simulated [{elapsed}<{remaining}]",
    ) as bar:
        for t, t1 in zip(steps, steps[1:]):
            given = next(inputs)
            events, truth = sim.step(t, t1, given)
            chunks.append(events)
            truths.append(truth)
            radiance = given.radiance
            pixel_s += (t1 - t) * np.array(
                [np.count_nonzero(radiance < DARK * white), np.count_nonzero(radiance > BRIGHT * white)]
            )
            bar.update(round(t1 * 1e6) - bar.n)
    events = np.concatenate(chunks) if chunks else np.empty(0, EVENT_DTYPE)
    return events, _stats(config.duration_s, truths, pixel_s, white)


def _stats(duration_s: float, truths, pixel_s: np.ndarray, white: float) -> SimStats:
    noise = np.concatenate([tr.noise for tr in truths])
    latency = np.concatenate([tr.latency_s for tr in truths])
    radiance = np.concatenate([tr.radiance for tr in truths])
    dark, bright = radiance < DARK * white, radiance > BRIGHT * white
    signal = ~noise
    matched = signal & np.isfinite(latency)

    def median(mask):
        return float(np.median(latency[mask & matched])) if (mask & matched).any() else float("nan")

    return SimStats(
        duration_s=duration_s,
        events=len(noise),
        noise_fraction=float(noise.mean()) if len(noise) else 0.0,
        noise_rate_dark_hz=float((noise & dark).sum() / max(pixel_s[0], 1e-12)),
        noise_rate_bright_hz=float((noise & bright).sum() / max(pixel_s[1], 1e-12)),
        latency_dark_s=median(dark),
        latency_bright_s=median(bright),
        latency_matched=float(matched.sum() / max(signal.sum(), 1)),
        dark_pixel_s=float(pixel_s[0]),
        bright_pixel_s=float(pixel_s[1]),
    )
