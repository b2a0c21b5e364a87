"""The house rules of ARCHITECTURE.md, read from the source with `ast`: imports only go
down the layers, no import cycle anywhere, no plugin named in core code, and the tests
mirror the package."""

import ast
import re
from pathlib import Path

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
#: The layers, bottom to top, and what is in each: a package (a folder) or a module. Imports only
#: go down (ALLOWED); docs/architecture.md's layout table is this one, each row's purpose the
#: first sentence of its docstring (test_the_documented_layout_is_the_layer_table).
LAYERS = {
    "bottom": (
        "eas_vo.types",
        "eas_vo.errors",
        "eas_vo.validation",
        "eas_vo.geometry",
        "eas_vo.camera",
        "eas_vo.concurrency",
        "eas_vo.logs",
    ),
    "middle": (
        "eas_vo.plugins",
        "eas_vo.registry",
        "eas_vo.io",
        "eas_vo.eventfile",
        "eas_vo.evaluation",
        "eas_vo.imu",
        "eas_vo.plots",
        "eas_vo.orb",
    ),
    "top": (
        "eas_vo.config",
        "eas_vo.pipeline",
        "eas_vo.experiments",
        "eas_vo.sequence",
        "eas_vo.slam",
        "eas_vo.api",
        "eas_vo.cli",
        "eas_vo.__main__",
    ),
    "plugins": ("eas_vo.frontends", "eas_vo.trackers", "eas_vo.backends", "eas_vo.datasets"),
}
PLUGIN_KINDS = set(LAYERS["plugins"])
#: Imports made on first use of a name, never at import time (PEP 562's module `__getattr__`):
#: the root exports the Python API so, and `import eas_vo` (every command's) stays light. They
#: are no edges of the graph, neither down the layers nor in a cycle;
#: test_the_root_imports_the_api_only_when_asked checks that they stay lazy.
LAZY_EXPORTS = {"eas_vo": {"eas_vo.api"}}


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
    for group, members in LAYERS.items():
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
    return {name: imports(name, tree, set(trees)) - LAZY_EXPORTS.get(name, set()) for name, tree in trees.items()}


def test_every_module_has_a_layer(graph):
    assert [m for m in graph if layer(m) == "unassigned"] == []


def test_imports_only_go_down(graph):
    wrong = [
        f"{m} ({layer(m)}) imports {d} ({layer(d)})"
        for m, deps in graph.items()
        for d in sorted(deps)
        if layer(d) not in ALLOWED[layer(m)]
    ]
    assert wrong == []


def test_a_plugin_imports_no_other_kind_of_plugin(graph):
    def kind(m):
        return next((k for k in PLUGIN_KINDS if m == k or m.startswith(k + ".")), None)

    wrong = [
        f"{m} imports {d}" for m, deps in graph.items() for d in deps if kind(m) and kind(d) and kind(d) != kind(m)
    ]
    assert wrong == []


def test_no_import_cycle(graph):
    state: dict[str, int] = {}  # 1 on the current path, 2 done

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d) :] + [m, d]))
            if d not in state:
                visit(d, path + [m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])


def test_the_root_imports_the_api_only_when_asked():
    """`import eas_vo` imports no module of the package (its lazy exports wait for their names);
    each name of its `__all__` is then eas_vo.api's."""
    import subprocess
    import sys

    code = (
        "import sys, eas_vo; loaded = sorted(m for m in sys.modules if m.startswith('eas_vo.')); "
        "exported = [getattr(eas_vo, name) is getattr(eas_vo.api, name) for name in eas_vo.__all__]; "
        "print(loaded, all(exported), len(exported))"
    )
    said = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPOSITORY.parent)
    assert said.stdout.split() == ["[]", "True", "5"], said.stderr


def test_core_code_names_no_plugin():
    """Core modules choose plugins through the registry only: no built-in plugin's name as a string
    (except defaults in config and the commands, and the paper's own experiment: its sources in
    the gallery, its grids and tables in paper, table1 and table2; the rotation benchmark's rows)."""
    from eas_vo import registry

    names = {n for kind in registry.KINDS for n in registry.available(kind)}
    core = REPOSITORY / "eas_vo"
    allowed = {
        core / "config.py",
        *(core / "experiments" / f"{name}.py" for name in ("gallery", "paper", "table1", "table2", "rotation")),
    }
    found = []
    for path in core.rglob("*.py"):
        if path in allowed or path.is_relative_to(core / "cli"):
            continue
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
        stem = test.stem[len("test_") :]
        candidates = [stem[: m.start()] for m in re.finditer(r"_|$", stem)]
        if not any(
            (REPOSITORY / folder / f"{c}.py").exists() or (REPOSITORY / folder / c).is_dir() for c in candidates
        ):
            orphans.append(str(test.relative_to(REPOSITORY)))
    assert orphans == []


def source_of(name: str) -> Path:
    """The folder (a package) or file (a module) of the installed name `name`, in the repository."""
    for folder, package in sorted(PACKAGES.items(), key=lambda item: -len(item[1])):  # eas_vo.frontends before eas_vo
        if name == package or name.startswith(package + "."):
            path = REPOSITORY.joinpath(folder, *name[len(package) :].strip(".").split("."))
            return path if path.is_dir() else path.with_suffix(".py")
    raise AssertionError(f"{name} is in no installed root")


def purpose(path: Path) -> str:
    """The first sentence of the docstring of a module or package (its __init__.py)."""
    file = path / "__init__.py" if path.is_dir() else path
    text = " ".join((ast.get_docstring(ast.parse(file.read_text())) or "").split("\n\n")[0].split())
    return re.split(r"(?<=\.)\s(?=[A-Z`])", text, maxsplit=1)[0].rstrip(".")


def documented_layout() -> str:
    """docs/architecture.md's layout table as LAYERS says it: a row per package or module."""
    rows = ["| layer | where | what it holds |", "|---|---|---|"]
    for group, members in LAYERS.items():
        for k, name in enumerate(members):
            path = source_of(name)
            shown = f"{path.relative_to(REPOSITORY)}/" if path.is_dir() else str(path.relative_to(REPOSITORY))
            rows.append(f"| {group if k == 0 else ''} | `{shown}` | {purpose(path)} |")
    return "\n".join(rows) + "\n"


def test_the_documented_layout_is_the_layer_table():
    """docs/architecture.md holds LAYERS's table between its markers, so the page cannot go stale:
    a package added, moved or re-described fails here, and the message holds the table to paste."""
    page = (REPOSITORY / "docs" / "architecture.md").read_text()
    start, end = "<!-- layout: tests/test_architecture.py -->\n", "<!-- end of layout -->"
    assert start in page and end in page, "docs/architecture.md lost its layout markers"
    shown = page.split(start, 1)[1].split(end, 1)[0]
    assert shown == documented_layout(), (
        "docs/architecture.md's layout table, as it should read:\n" + documented_layout()
    )


def test_every_package_of_the_tree_has_a_layer_and_a_purpose():
    """Each folder with an __init__.py under the installed roots, and each top-level core module,
    belongs to a layer and says in its docstring what it holds."""
    missing = []
    for name in modules():
        if layer(name) == "unassigned":
            missing.append(f"{name}: no layer")
    for path in sorted((REPOSITORY / "eas_vo").rglob("*.py")):
        if not (ast.get_docstring(ast.parse(path.read_text())) or "").strip():
            missing.append(f"{path.relative_to(REPOSITORY)}: no docstring")
    assert missing == []


@pytest.mark.slow
def test_a_wheel_holds_every_subpackage_of_the_tree(tmp_path):
    """A normal (non-editable) install gets every package of the tree: setup.py finds them with
    setuptools' package discovery, so a new subpackage needs no hand-kept list."""
    import subprocess
    import sys
    import zipfile

    source = tmp_path / "source"
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=REPOSITORY, capture_output=True, check=True).stdout
    for name in filter(None, tracked.decode().split("\0")):
        if (REPOSITORY / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            (source / name).write_bytes((REPOSITORY / name).read_bytes())
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            "--wheel-dir",
            str(tmp_path / "wheel"),
            str(source),
        ],
        check=True,
        capture_output=True,
    )
    (wheel,) = (tmp_path / "wheel").glob("*.whl")
    held = {
        n.removesuffix("/__init__.py").replace("/", ".")
        for n in zipfile.ZipFile(wheel).namelist()
        if n.endswith("/__init__.py")
    }
    expected = {name for name in modules() if source_of(name).is_dir()} | {"eas_vo.configs"}
    assert expected <= held, sorted(expected - held)
