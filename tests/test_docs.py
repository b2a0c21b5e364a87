"""The user documentation holds what the code does: README.md and docs/*.md link only to
files and headings that exist, every `eas-vo ...` line in their code blocks parses with the
CLI's own parser, the README's plugin is the package the plugin tests install, and the
README's quoted summary line is what its first command prints."""

import re
import shlex
import unicodedata
from pathlib import Path

import pytest

from eas_vo.cli.main import build_parser, main
from helpers import REPOSITORY, code_blocks, shell_commands

PAGES = [REPOSITORY / "README.md", *sorted((REPOSITORY / "docs").glob("*.md"))]
PLUGIN_PACKAGE = REPOSITORY / "tests" / "plugin_example"
#: The start of the README's quoted summary line of its first command.
FIRST_RUN = "eas+klt+chain on synthetic:default:"


def page_id(path: Path) -> str:
    return str(path.relative_to(REPOSITORY))


def prose(text: str) -> str:
    """The text outside fenced code blocks."""
    return re.sub(r"^```\w*\n.*?^```", "", text, flags=re.S | re.M)


def anchors(text: str) -> set[str]:
    """GitHub's anchors for a Markdown text's headings: lower case, punctuation dropped,
    spaces to hyphens, a repeated heading numbered -1, -2, ..."""
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6}\s+(.+?)\s*#*$", prose(text), re.M):
        plain = re.sub(r"[`*]|\[([^\]]*)\]\([^)]*\)", lambda m: m.group(1) or "", heading)
        slug = "".join(c for c in unicodedata.normalize("NFKC", plain.lower()) if c.isalnum() or c in " -_").replace(
            " ", "-"
        )
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def relative_links(text: str) -> list[str]:
    """Targets of the Markdown links and images outside code that are not URLs."""
    targets = re.findall(r"!?\[[^\]]*\]\(([^)\s]+)\)", re.sub(r"`[^`\n]*`", "", prose(text)))
    return [t for t in targets if not re.match(r"[a-z][a-z0-9+.-]*:", t)]


def broken_links(path: Path) -> list[str]:
    broken = []
    for target in relative_links(path.read_text()):
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / file_part).resolve() if file_part else path
        if not linked.exists():
            broken.append(f"{target}: no file {linked}")
        elif anchor and (linked.suffix != ".md" or anchor not in anchors(linked.read_text())):
            broken.append(f"{target}: no heading #{anchor} in {linked.name}")
    return broken


@pytest.mark.parametrize("path", PAGES, ids=page_id)
def test_every_relative_link_resolves(path):
    assert broken_links(path) == []


def test_the_link_check_sees_broken_files_and_anchors(tmp_path):
    """The checker itself: a missing file, a missing heading and a good heading of another page."""
    (tmp_path / "other.md").write_text("# Time offsets: the ground truth's clock\n\n## A `code` heading\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[a](other.md#time-offsets-the-ground-truths-clock) [b](other.md#a-code-heading) "
        "[c](missing.md) [d](other.md#nope) [e](#here) [f](https://example.org/x.md)\n\n## Here\n"
        "```\n[g](inside-code.md)\n```\n"
    )
    assert [b.split(":")[0] for b in broken_links(page)] == ["missing.md", "other.md#nope"]


def command_lines(text: str) -> list[list[str]]:
    """Every `eas-vo ...` command in the text's code blocks, as argv after `eas-vo`."""
    return [words[1:] for _, words in shell_commands(text) if Path(words[0]).name == "eas-vo"]


DOCUMENTED_COMMANDS = [(page_id(path), argv) for path in PAGES for argv in command_lines(path.read_text())]


def test_the_documentation_shows_commands():
    pages = {page for page, _ in DOCUMENTED_COMMANDS}
    assert {"README.md", "docs/reproducing.md", "docs/datasets.md"} <= pages
    assert ["run", "--frontend", "eas", "--backend", "chain"] in [argv for _, argv in DOCUMENTED_COMMANDS]


@pytest.mark.parametrize("page, argv", DOCUMENTED_COMMANDS, ids=[f"{p}: {' '.join(a)}" for p, a in DOCUMENTED_COMMANDS])
def test_every_documented_command_parses(page, argv, capsys):
    """What `eas-vo` would do with the line up to running it: the CLI's own parser, no run."""
    try:
        build_parser().parse_args(argv)
    except SystemExit as stop:
        said = capsys.readouterr()
        assert stop.code == 0, f"{page}: eas-vo {shlex.join(argv)}: {said.err.strip()}"


def test_a_command_that_does_not_parse_is_caught(capsys):
    argv = command_lines("```bash\neas-vo run --frontend eas --backnd chain  # a typo\n```\n")[0]
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(argv)
    assert stop.value.code == 2 and "--backnd" in capsys.readouterr().err


def test_the_readme_plugin_is_the_package_the_tests_install():
    """The README's plugin, character for character, and its pyproject.toml's entry point, as
    written there, are tests/plugin_example's, which tests/eas_vo/test_plugins.py installs with
    pip and runs."""
    readme = (REPOSITORY / "README.md").read_text()
    module = [b for b in code_blocks(readme, "python") if "(Frontend):" in b]
    pyproject = [b for b in code_blocks(readme, "toml") if "[project.entry-points." in b]
    assert len(module) == 1 and len(pyproject) == 1
    assert module[0] == (PLUGIN_PACKAGE / "eas_vo_edges.py").read_text()
    assert pyproject[0] in (PLUGIN_PACKAGE / "pyproject.toml").read_text()


def test_the_plugin_guides_event_tracker_is_the_package_the_tests_install():
    """docs/plugins.md's event-reading tracker, character for character, is tests/plugin_example's."""
    page = (REPOSITORY / "docs" / "plugins.md").read_text()
    module = [b for b in code_blocks(page, "python") if "needs_events = True" in b]
    assert module == [(PLUGIN_PACKAGE / "eas_vo_evflow.py").read_text()]


def comparable(summary: str) -> str:
    """A summary line without what varies between machines and runs: speed and folder."""
    return re.sub(r", [0-9.]+ frames/s -> \S+$", "", summary.strip())


def test_the_summary_check_ignores_only_speed_and_folder():
    line = f"{FIRST_RUN} 200 frames (1 first, 199 ok), average NC 226.5, average APE 0.1663 rad (9.53 deg), 13.6 frames/s -> runs/a"
    assert comparable(line) == comparable(line.replace("13.6", "250.1").replace("runs/a", "/tmp/b"))
    assert comparable(line) != comparable(line.replace("0.1663", "0.1662"))
    assert comparable(line) != comparable(line.replace("199 ok", "198 ok, 1 weak"))


@pytest.mark.slow
def test_the_readme_quotes_the_first_runs_summary_line(tmp_path, capsys):
    """The README's first command, run (the embedded default sequence, about a minute once
    simulated), prints the summary line the README quotes, but for speed and folder."""
    quoted = [line for line in (REPOSITORY / "README.md").read_text().splitlines() if line.startswith(FIRST_RUN)]
    assert len(quoted) == 1, f"the README quotes the first run's summary line once, starting {FIRST_RUN!r}"
    assert main(["run", "--frontend", "eas", "--backend", "chain", "--out", str(tmp_path / "run"), "--quiet"]) == 0
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith(FIRST_RUN)]
    assert [comparable(line) for line in printed] == [comparable(quoted[0])]


FORBIDDEN = ("this session", "this vm", "until this release", "two reviews", "round two")


@pytest.mark.parametrize("path", PAGES, ids=page_id)
def test_the_documentation_speaks_to_an_outside_reader(path):
    """No words that mean something only inside the project: issue numbers and its history's labels."""
    text = path.read_text()
    assert re.findall(r"(?<![\w&])#\d+\b", prose(text)) == []
    assert [w for w in FORBIDDEN if w in text.lower()] == []
