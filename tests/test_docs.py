"""Every command the README and the docs/ pages show runs as shown (docs never rot), and every page is linked.

A command is a line of an ``sh`` code block, ``contoursim ...``: it runs through the
CLI's ``main`` from the repository root, as a user who copied the line would,
with ``--out`` into a temporary folder and report files beside it. (The example
scripts are run by test_examples.py, the benchmarks by test_benchmarks.py.)
"""

import re
import shlex

import pytest

from conftest import ROOT

from contoursim.cli import main

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _commands():
    found = []
    for page in PAGES:
        for block in re.findall(r"```sh\n(.*?)```", page.read_text(encoding="utf-8"), re.S):
            found += [(page.relative_to(ROOT).as_posix(), line.strip()) for line in block.splitlines() if line.strip()]
    return found


COMMANDS = _commands()


def test_the_docs_show_commands():
    assert len(COMMANDS) >= 5, COMMANDS


@pytest.mark.parametrize("page, line", COMMANDS, ids=[f"{p}: {line}" for p, line in COMMANDS])
def test_every_command_shown_runs(page, line, tmp_path, monkeypatch, capsys):
    words = shlex.split(line)
    assert words[0] == "contoursim", f"{page}: an sh block holds contoursim commands only, got {line!r}"
    monkeypatch.chdir(ROOT)
    args = [str(tmp_path / a) if a.endswith(".json") else a for a in words[1:]]  # reports beside the output
    assert main(args + ["--out", str(tmp_path / "out")]) == 0, capsys.readouterr().err


def test_every_docs_page_is_linked_from_the_readme_and_its_links_resolve():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for page in PAGES[1:]:
        if page.name != "README.md":
            assert f"(docs/{page.name})" in readme, f"{page.name} is not linked from README.md"
    for page in PAGES:
        for target in re.findall(r"\]\((?!https?:|#|mailto:)([^)#]+)", page.read_text(encoding="utf-8")):
            assert (page.parent / target).exists(), f"{page.relative_to(ROOT)} links to {target}, which is not there"


def test_the_sweep_page_names_the_strategy_settings_a_sweep_takes():
    """The page listed `feedforward`: `velocity`, `acceleration`, which a sweep refuses ("its settings:
    velocity_fraction, acceleration_fraction")."""
    from contoursim.compensation import STRATEGY_KEYS

    page = (ROOT / "docs" / "sweeps-and-fleets.md").read_text(encoding="utf-8")
    listed = re.search(r"`strategy\.<strategy>\.<gain>` \((.*?)\)", page, re.S).group(1)
    named = {}
    for group in listed.split(";"):  # "`ccc_arc`/`ccc_linear`: `kp_per_s`, `ki_per_s2`, `kd`"
        strategies, _, keys = group.partition(":")
        for strategy in re.findall(r"`(\w+)`", strategies):
            named[strategy] = re.findall(r"`(\w+)`", keys)
    assert named == {name: list(keys) for name, keys in STRATEGY_KEYS.items()}
