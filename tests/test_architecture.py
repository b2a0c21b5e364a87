"""The house rules of ARCHITECTURE.md, read from the source with `ast`: imports only go
down the layers, no import cycle anywhere, no plugin named in core code, and the tests
mirror the package."""

import ast
import re

import pytest

from helpers import REPOSITORY

#: Source folder -> installed package.
PACKAGES = {
    "eas_vo": "eas_vo",
    "frontends": "eas_vo.frontends",
    "trackers": "eas_vo.trackers",
    "backends": "eas_vo.backends",
    "datasets": "eas_vo.datasets",
}
BOTTOM = {"eas_vo.types", "eas_vo.errors", "eas_vo.validation", "eas_vo.geometry", "eas_vo.concurrency", "eas_vo.logs"}
MIDDLE = {"eas_vo.plugins", "eas_vo.registry", "eas_vo.io", "eas_vo.eventfile", "eas_vo.evaluation", "eas_vo.imu_check", "eas_vo.plots",
          "eas_vo.orb"}
TOP = {"eas_vo.config", "eas_vo.pipeline", "eas_vo.compare", "eas_vo.gallery", "eas_vo.orbslam", "eas_vo.reproduce", "eas_vo.sequence",
       "eas_vo.slam",
       "eas_vo.cli", "eas_vo.__main__"}
PLUGIN_KINDS = {"eas_vo.frontends", "eas_vo.trackers", "eas_vo.backends", "eas_vo.datasets"}


def modules() -> dict[str, ast.Module]:
    """Every source module of the package, by installed name."""
    found = {}
    for folder, package in PACKAGES.items():
        for path in sorted((REPOSITORY / folder).rglob("*.py")):
            parts = list(path.relative_to(REPOSITORY / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join([package, *parts])] = ast.parse(path.read_text(), str(path))
    return found


def imports(name: str, tree: ast.Module, known: set[str]) -> set[str]:
    """The package's modules that `name` imports, at any depth of its code."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(name.split(".")[: -node.level] + ([base] if base else []))
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


def layer(module: str) -> str:
    for group, members in (("bottom", BOTTOM), ("middle", MIDDLE), ("top", TOP), ("plugins", PLUGIN_KINDS)):
        if any(module == m or module.startswith(m + ".") for m in members):
            return group
    return "root" if module == "eas_vo" else "unassigned"


ALLOWED = {
    "bottom": {"bottom", "root"},
    "middle": {"bottom", "middle", "root"},
    "plugins": {"bottom", "middle", "plugins", "root"},
    "top": {"bottom", "middle", "top", "plugins", "root"},
    "root": set(),
}


@pytest.fixture(scope="module")
def graph():
    trees = modules()
    return {name: imports(name, tree, set(trees)) for name, tree in trees.items()}


def test_every_module_has_a_layer(graph):
    assert [m for m in graph if layer(m) == "unassigned"] == []


def test_imports_only_go_down(graph):
    wrong = [f"{m} ({layer(m)}) imports {d} ({layer(d)})" for m, deps in graph.items() for d in sorted(deps)
             if layer(d) not in ALLOWED[layer(m)]]
    assert wrong == []


def test_a_plugin_imports_no_other_kind_of_plugin(graph):
    def kind(m):
        return next((k for k in PLUGIN_KINDS if m == k or m.startswith(k + ".")), None)

    wrong = [f"{m} imports {d}" for m, deps in graph.items() for d in deps if kind(m) and kind(d) and kind(d) != kind(m)]
    assert wrong == []


def test_no_import_cycle(graph):
    state: dict[str, int] = {}  # 1 on the current path, 2 done

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d):] + [m, d]))
            if d not in state:
                visit(d, path + [m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])


def test_core_code_names_no_plugin():
    """Core modules choose plugins through the registry only: no built-in plugin's name as a string
    (except defaults in config and cli, and the paper's own experiment: its sources in gallery,
    its tables in reproduce)."""
    from eas_vo import registry

    names = {n for kind in registry.KINDS for n in registry.available(kind)}
    core = [p for p in (REPOSITORY / "eas_vo").rglob("*.py") if p.stem not in {"config", "cli", "gallery", "reproduce"}]
    found = []
    for path in core:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
                found.append(f"{path.name}:{node.lineno} {node.value!r}")
    assert found == []


def test_tests_mirror_the_package():
    """tests/<folder>/test_<module>[_<aspect>].py belongs to <folder>/<module>.py (or a package of
    that name); tests/ itself holds only repository-wide checks such as this file."""
    orphans = []
    for test in sorted((REPOSITORY / "tests").rglob("test_*.py")):
        folder = test.parent.relative_to(REPOSITORY / "tests")
        if not folder.parts or folder.parts[0] in ("support", "plugin_example"):
            continue
        stem = test.stem[len("test_"):]
        candidates = [stem[:m.start()] for m in re.finditer(r"_|$", stem)]
        if not any((REPOSITORY / folder / f"{c}.py").exists() or (REPOSITORY / folder / c).is_dir() for c in candidates):
            orphans.append(str(test.relative_to(REPOSITORY)))
    assert orphans == []
