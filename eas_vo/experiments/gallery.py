"""Every frontend's image of chosen frames, side by side (the paper's Fig. 1)."""

from __future__ import annotations

import numpy as np

from eas_vo import config as config_mod
from eas_vo import registry
from eas_vo.errors import EasVoError
from eas_vo.pipeline.parts import check_frame

#: The paper's order of image sources (Fig. 1, Table 1); other frontends follow by name.
PAPER_ORDER = ("original", "histeq", "slice", "ts", "sits", "eas")

#: Each of the paper's sources' colour in every figure of compare (and reproduce); other
#: frontends take plots.SPARE_COLOURS.
PAPER_COLOURS = {
    "original": "tab:blue",
    "histeq": "tab:orange",
    "slice": "tab:green",
    "eas": "tab:red",
    "ts": "tab:purple",
    "sits": "tab:brown",
}


def frontend_images(
    dataset_spec: str | None,
    frame_indices: list[int],
    frontends: list[str] | None = None,
    config_file=None,
    assignments: list[str] = (),
) -> tuple[list[str], dict]:
    """Images {(frame index, frontend name): uint8 image, or None if the frontend cannot run there}.

    Every sample up to the last chosen one goes through every frontend, so that stateful
    frontends (ts, sits) have consumed the events before each chosen frame.
    """
    drawable = [n for n in registry.available("frontends") if registry.get("frontends", n).makes_images]
    names = frontends or sorted(
        drawable, key=lambda n: (PAPER_ORDER.index(n) if n in PAPER_ORDER else len(PAPER_ORDER), n)
    )
    for name in names:
        if name in registry.available("frontends") and name not in drawable:
            raise EasVoError(f"frontend {name!r} makes no image to draw")
    base = config_mod.resolve(config_file, {"dataset": dataset_spec}, assignments)
    dataset = registry.open_dataset(base.run.dataset, base.dataset)
    n_samples = len(dataset.frame_times())
    bad = [k for k in frame_indices if not 0 <= k < n_samples]
    if bad:
        raise EasVoError(f"{dataset.label}: frame {bad[0]} does not exist (it has {n_samples})")
    built = {}
    for name in names:
        cfg = config_mod.resolve(config_file, {"dataset": dataset_spec, "frontend": name}, assignments)
        cls = registry.get("frontends", name)
        if cls.needs_frames and dataset.load_frame(0) is None:
            continue
        built[name] = cls(cfg.frontend, dataset.camera)
    images = {(k, name): None for k in frame_indices for name in names}
    wanted = set(frame_indices)
    for sample in dataset.samples():
        if sample.index > max(frame_indices):
            break
        check_frame(sample.frame, dataset, sample.index, sample.t)
        for name, frontend in built.items():
            image = frontend(sample)
            if sample.index in wanted:
                images[(sample.index, name)] = np.asarray(image)
    return names, images
