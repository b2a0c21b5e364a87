"""`synthetic:NAME`: a simulated dim-scene DAVIS sequence, generated once and cached."""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.errors import EasVoError
from eas_vo.io import cache_dir
from eas_vo.plugins import NoConfig

#: Named sequences. `default` is the embedded sequence `eas-vo run` uses.
PRESETS = {
    "default": SimConfig(duration_s=10.0, seed=0),
    "short": SimConfig(duration_s=3.0, seed=1),
}


def sequence_folder(name: str, progress: bool = True) -> Path:
    """The cached folder of preset `name`, simulating it first if needed."""
    if name not in PRESETS:
        raise EasVoError(f"unknown synthetic sequence {name!r}; available: {', '.join(PRESETS)}")
    config = PRESETS[name]
    digest = hashlib.sha1(config.fingerprint().encode()).hexdigest()[:12]
    folder = cache_dir() / "synthetic" / f"{name}-{digest}"
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
    Config = NoConfig

    @classmethod
    def can_open(cls, location: str) -> bool:
        """Never by guessing: a synthetic sequence is named explicitly, `synthetic:NAME`."""
        return False

    def __init__(self, name: str = "default", config=None):
        super().__init__(sequence_folder(name or "default", progress=sys.stderr.isatty()))
        self.label = f"synthetic:{name or 'default'}"
