"""`synthetic:NAME`: a simulated dim-scene DAVIS sequence, generated once and cached."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from eas_vo.camera import LENS_MODELS
from eas_vo.datasets.calibration import MAX_SENSOR_PX, camera_problem
from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.datasets.simulator.generate import SENSORS, SimCamera
from eas_vo.datasets.simulator.sensor import DvsModel
from eas_vo.errors import ConfigError, EasVoError
from eas_vo.io.cache import cache_folder
from eas_vo.validation import check_choice, check_range

logger = logging.getLogger(__name__)

#: Named sequences. `default` is the embedded sequence `eas-vo run` uses. `walk` (and its short
#: first 5 s, `walk_short`) is a hand-held walk through a lit room: the translation ten times the
#: default's, the default's rotation at a constant pace, a hundred times the light: the parallax
#: and texture monocular SLAM needs (docs/synthetic.md, "A walk for monocular SLAM").
_WALK = {"illumination": 100.0, "translation_scale": 10.0, "speed_growth": 0.0}
PRESETS = {
    "default": SimConfig(duration_s=10.0, seed=0),
    "short": SimConfig(duration_s=3.0, seed=1),
    "walk": SimConfig(duration_s=10.0, seed=2, **_WALK),
    "walk_short": SimConfig(duration_s=5.0, seed=2, **_WALK),
}


@dataclass(frozen=True)
class SyntheticConfig(DvsModel):
    """The scene's light, the camera's speed and translation, the camera and the DVS pixel
    (DvsModel's fields, same units and defaults). Light, speed and translation scale the
    preset's own (PRESETS: the default sequence's are all 1).

    Attributes:
        illumination: scale of the scene's light (1.0: the preset's; the default one is the dim
            room, 0.1 ten times darker).
        speed: scale of the motion's speed (1.0: the preset's; the default one is hand-held);
            the same path, travelled faster (docs/synthetic.md, "Simulating other sequences",
            gives the speeds).
        translation_scale: scale of the motion's translation (1.0: the preset's; the default
            one moves 4-5 cm per axis, `walk` tens of cm); the same path, its positions scaled.
        sensor: the camera's preset (SENSORS): `davis240` (240x180, radial-tangential lens) or
            `davis346` (346x260, MVSEC's calibration: an equidistant lens).
        width, height: another sensor size [px] (0: the preset's), with the preset's diagonal
            field of view unless `focal_px` is given.
        focal_px: the focal length [px] (0: the preset's, scaled to the size).
        lens: `radtan` or `equidistant` ("": the preset's); dist: its coefficients in that model's
            order (empty: the preset's for its own lens, none for the other).
        duration_s: the length simulated [s] (0: the preset's; a shorter sequence for a quick
            check, simulated and cached on its own).
    """

    illumination: float = 1.0
    speed: float = 1.0
    translation_scale: float = 1.0
    sensor: str = "davis240"
    width: int = 0
    height: int = 0
    focal_px: float = 0.0
    lens: str = ""
    dist: tuple = ()
    duration_s: float = 0.0

    def camera(self) -> SimCamera:
        """The simulated camera these values give."""
        preset = SENSORS[self.sensor]
        cam = preset.resized(self.width or preset.width, self.height or preset.height)
        if self.focal_px:
            cam = dataclasses.replace(cam, fx=self.focal_px, fy=self.focal_px)
        lens = self.lens or cam.lens
        if self.dist:
            dist = tuple(float(v) for v in self.dist)
        else:
            dist = cam.dist if lens == cam.lens else (0.0,) * len(LENS_MODELS[lens])
        return dataclasses.replace(cam, lens=lens, dist=dist)

    def validate(self) -> None:
        check_range(self, "illumination", 0.0, 1e6, lo_open=True)
        check_range(self, "speed", 0.0, 20.0, lo_open=True)
        check_range(self, "translation_scale", 0.0, 100.0)
        check_range(self, "duration_s", 0.0, 3600.0)
        check_choice(self, "sensor", SENSORS)
        check_range(self, "width", 0, MAX_SENSOR_PX)
        check_range(self, "height", 0, MAX_SENSOR_PX)
        check_range(self, "focal_px", 0.0, 100.0 * MAX_SENSOR_PX)
        check_choice(self, "lens", ("", *LENS_MODELS))
        lens = self.lens or SENSORS[self.sensor].lens
        names = LENS_MODELS[lens]
        if self.dist and (
            len(self.dist) != len(names)
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in self.dist)
        ):
            raise ConfigError(
                f"dist = {list(self.dist)!r}: the {lens} lens takes {len(names)} finite numbers ({' '.join(names)})"
            )
        cam = self.camera()
        problem = camera_problem([cam.fx, cam.fy, cam.cx, cam.cy, *cam.dist], cam.width, cam.height, cam.lens)
        if problem:
            raise ConfigError(
                f"{'dist' if 'distortion' in problem else 'focal_px'}: the camera is impossible: {problem}"
            )
        check_range(self, "contrast_threshold", 0.01, 5.0)
        check_range(self, "threshold_sigma", 0.0, 1.0)
        check_range(self, "refractory_s", 0.0, 1.0)
        check_range(self, "log_eps", 0.0, 1e3, lo_open=True)
        check_range(self, "cutoff_hz", 0.0, 1e6)
        check_range(self, "white_radiance", 0.0, 1e9, lo_open=True)
        check_range(self, "shot_noise_rate_hz", 0.0, 1e4)
        check_range(self, "shot_noise_bright_factor", 0.0, 100.0)
        check_range(self, "leak_rate_hz", 0.0, 1e4)
        check_range(self, "leak_spread_decades", 0.0, 3.0)
        check_range(self, "hot_pixel_fraction", 0.0, 1.0)
        check_range(self, "hot_pixel_rate_hz", 0.0, 1e6)

    def applied_to(self, preset: SimConfig) -> SimConfig:
        """The preset seen by this camera and pixel, its light, speed and translation scaled."""
        dvs = DvsModel(**{f.name: getattr(self, f.name) for f in dataclasses.fields(DvsModel)})
        return dataclasses.replace(
            preset,
            duration_s=self.duration_s or preset.duration_s,
            illumination=preset.illumination * self.illumination,
            speed=preset.speed * self.speed,
            translation_scale=preset.translation_scale * self.translation_scale,
            dvs=dvs,
            camera=self.camera(),
        )


def sequence_folder(name: str, config: SyntheticConfig | None = None, progress: bool = True) -> Path:
    """The cached folder of preset `name` under `config`, simulating it first if needed; the
    folder is keyed by every resolved simulator value, so each configuration is simulated once."""
    if name not in PRESETS:
        raise EasVoError(f"unknown synthetic sequence {name!r}; available: {', '.join(PRESETS)}")
    config = (config or SyntheticConfig()).applied_to(PRESETS[name])
    digest = hashlib.sha1(config.fingerprint().encode()).hexdigest()[:12]
    folder = (
        cache_folder("synthetic", "simulated sequences; simulated again when next needed (about 40 s each)")
        / f"{name}-{digest}"
    )
    if not (folder / "images.txt").exists():
        if progress:
            logger.info(f"simulating synthetic:{name} ({config.duration_s:g} s) into {folder} (once)")
        tmp = folder.with_name(f".{folder.name}.{os.getpid()}.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        try:
            simulate(config, tmp, progress=progress)
            _put_in_place(tmp, folder)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _put_in_place(simulated: Path, folder: Path) -> None:
    """Rename the finished simulation to `folder`, unless another process (a second run, a
    parallel test) put the same simulation there meanwhile: a complete folder is never removed
    under its readers; an incomplete one (no images.txt) is renamed aside and removed first."""
    if (folder / "images.txt").exists():
        return
    if folder.exists():
        aside = folder.with_name(f".{folder.name}.{os.getpid()}.old")
        os.replace(folder, aside)
        shutil.rmtree(aside, ignore_errors=True)
    try:
        os.replace(simulated, folder)
    except OSError:
        if not (folder / "images.txt").exists():
            raise


def _label_value(value) -> str:
    if isinstance(value, tuple):
        return "[" + ",".join(f"{v:g}" for v in value) + "]"
    return value if isinstance(value, str) else f"{value:g}"


class SyntheticDataset(EcdFolderDataset):
    """A simulated sequence (textured HDR room, hand-held motion), read like an ECD folder."""

    name = "synthetic"
    description = f"simulated dim-scene DAVIS sequence: synthetic:NAME, NAME in {', '.join(PRESETS)}"
    Config = SyntheticConfig

    @classmethod
    def can_open(cls, location: str) -> bool:
        """Never by guessing: a synthetic sequence is named explicitly, `synthetic:NAME`."""
        return False

    @classmethod
    def catalogue(cls) -> dict[str, str]:
        """None: synthetic sequences are simulated on first use, never downloaded."""
        return {}

    def __init__(self, name: str = "default", config: SyntheticConfig | None = None):
        config = config or SyntheticConfig()
        super().__init__(sequence_folder(name or "default", config, progress=sys.stderr.isatty()))
        changed = {
            f.name: getattr(config, f.name) for f in dataclasses.fields(config) if getattr(config, f.name) != f.default
        }
        self.label = f"synthetic:{name or 'default'}" + "".join(f" {k}={_label_value(v)}" for k, v in changed.items())
