"""The cells of a grid: datasets x frontends x methods (tracker + backend) x sweep points, each
with its folder name and its configuration overrides."""

from __future__ import annotations

import hashlib
import itertools
from dataclasses import dataclass
from pathlib import Path

from eas_vo import registry
from eas_vo.config import NO_IMAGES, parse_set
from eas_vo.errors import EasVoError
from eas_vo.io.text import slug


@dataclass(frozen=True)
class Method:
    """A column of the table: a tracker, a backend and the settings ((key, value text), ...)
    its cells run with beyond the grid's configuration."""

    tracker: str
    backend: str
    settings: tuple = ()

    @property
    def label(self) -> str:
        """`klt+gtsam`, with its settings: `klt+gtsam (keyframe_interval=3)`."""
        keys = " ".join(f"{k.split('.')[-1]}={v}" for k, v in self.settings)
        return f"{self.tracker}+{self.backend}" + (f" ({keys})" if keys else "")


def grid_methods(trackers: list[str], backends: list[str]) -> list[Method]:
    """Every tracker with every backend, as configured."""
    return [Method(t, b) for t, b in itertools.product(trackers, backends)]


@dataclass(frozen=True)
class Cell:
    """One run of the grid; `folder` is relative to the experiment's output folder."""

    dataset: str
    frontend: str
    tracker: str
    backend: str
    sweep: tuple  # ((key, value text), ...)
    dataset_name: str = ""  # distinct within its grid (plan); default: the dataset's slug
    settings: tuple = ()  # the method's own ((key, value text), ...): Method.settings

    @property
    def method(self) -> Method:
        """The table column the cell belongs to."""
        return Method(self.tracker, self.backend, self.settings)

    @property
    def sweep_label(self) -> str:
        return " ".join(f"{k}={v}" for k, v in self.sweep)

    @property
    def folder(self) -> str:
        parts = [f"{self.frontend}_{self.tracker}_{self.backend}"]
        parts += [f"{k.split('.')[-1]}-{v}" for k, v in self.settings + self.sweep]
        return f"{self.dataset_name or slug(self.dataset)}/{slug('_'.join(parts))}"


def parse_sweeps(sweeps: list[str]) -> list[tuple[str, list[str]]]:
    """`frontend.n=2000,4000` -> [('frontend.n', ['2000', '4000'])], keys validated."""
    out = []
    for sweep in sweeps:
        key, sep, values = sweep.partition("=")
        parse_set(f"{key}=0")  # the key's form
        items = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not items:
            raise EasVoError(f"--sweep {sweep!r}: expected SECTION.KEY=V1,V2,...")
        out.append((key.strip(), items))
    return out


def plan(datasets: list[str], frontends: list[str], methods: list[Method], sweeps: list[str]) -> list[Cell]:
    """The cartesian grid of cells."""
    parsed = parse_sweeps(sweeps)
    points = [tuple(zip([k for k, _ in parsed], combo)) for combo in itertools.product(*[v for _, v in parsed])]
    names = dataset_names(datasets)
    trackers = registry.available("trackers")  # an unknown one is its cells' failure, as any bad setting

    def frontend(f: str, tracker: str) -> str:
        return NO_IMAGES if tracker in trackers and not trackers[tracker].reads_images else f

    cells = [
        Cell(d, frontend(f, m.tracker), m.tracker, m.backend, point, names[d], m.settings)
        for d, f, m, point in itertools.product(datasets, frontends, dict.fromkeys(methods), points or [()])
    ]
    return list(dict.fromkeys(cells))  # a tracker that reads no images runs once, with the `no_image` frontend


def dataset_names(datasets: list[str]) -> dict[str, str]:
    """A distinct file-name-safe name per dataset spec: its last path component, with as many
    parent components as it takes to tell it from the others (`a-hdr_boxes`, `b-hdr_boxes`)."""

    def tail(spec: str, depth: int) -> str:
        parts = Path(spec.rstrip("/")).parts or (spec,)
        return slug("-".join(parts[-depth:]))

    names = {}
    for spec in dict.fromkeys(datasets):
        depth = 1
        while any(tail(other, depth) == tail(spec, depth) for other in datasets if other != spec) and depth < len(
            Path(spec).parts
        ):
            depth += 1
        names[spec] = tail(spec, depth)
    if len(set(names.values())) < len(names):  # still equal (e.g. `x` and `x/`): tell apart by hash
        names = {spec: f"{name}-{hashlib.sha1(spec.encode()).hexdigest()[:6]}" for spec, name in names.items()}
    return names
