"""`synthetic:NAME`: a simulated dim-scene DAVIS sequence, generated once and cached."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.datasets.simulator.sensor import DvsModel
from eas_vo.errors import EasVoError
from eas_vo.io import cache_folder
from eas_vo.validation import check_range

#: Named sequences. `default` is the embedded sequence `eas-vo run` uses.
PRESETS = {
    "default": SimConfig(duration_s=10.0, seed=0),
    "short": SimConfig(duration_s=3.0, seed=1),
}


@dataclass(frozen=True)
class SyntheticConfig(DvsModel):
    """The scene's light, the camera's speed and the DVS pixel (DvsModel's fields, same units
    and defaults).

    Attributes:
        illumination: scale of the scene's light (1.0: the default dim room, 0.1: ten times darker).
        speed: scale of the motion's speed (1.0: hand-held, 44 deg/s mean; 4.0: 177 deg/s, more
            than the real excerpt's 147 over its 30 s); the same path, travelled faster.
    """

    illumination: float = 1.0
    speed: float = 1.0

    def validate(self) -> None:
        check_range(self, "illumination", 0.0, 1e6, lo_open=True)
        check_range(self, "speed", 0.0, 20.0, lo_open=True)
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
        """The preset seen under this light by this pixel, at this speed."""
        dvs = DvsModel(**{f.name: getattr(self, f.name) for f in dataclasses.fields(DvsModel)})
        return dataclasses.replace(preset, illumination=self.illumination, speed=self.speed, dvs=dvs)


def sequence_folder(name: str, config: SyntheticConfig | None = None, progress: bool = True) -> Path:
    """The cached folder of preset `name` under `config`, simulating it first if needed; the
    folder is keyed by every resolved simulator value, so each configuration is simulated once."""
    if name not in PRESETS:
        raise EasVoError(f"unknown synthetic sequence {name!r}; available: {', '.join(PRESETS)}")
    config = (config or SyntheticConfig()).applied_to(PRESETS[name])
    digest = hashlib.sha1(config.fingerprint().encode()).hexdigest()[:12]
    folder = cache_folder("synthetic", "simulated sequences; simulated again when next needed (about 40 s each)") / f"{name}-{digest}"
    if not (folder / "images.txt").exists():
        if progress:
            print(f"eas-vo: simulating synthetic:{name} ({config.duration_s:g} s) into {folder} (once)", file=sys.stderr)
        tmp = folder.with_name(f".{folder.name}.{os.getpid()}.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        try:
            simulate(config, tmp, progress=progress)
            shutil.rmtree(folder, ignore_errors=True)
            os.replace(tmp, folder)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


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
        changed = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if getattr(config, f.name) != f.default}
        self.label = f"synthetic:{name or 'default'}" + "".join(f" {k}={v:g}" for k, v in changed.items())
