"""The README's examples run as written.

* Shell blocks marked ``<!-- readme-test: ... -->`` run line by line, in order, in a folder that
  holds what ``mrstereo demo --out mrstereo-demo`` writes and these examples read (a small
  corridor dataset, its map and its calibration), and must write the files they name.
* Every ``mrstereo COMMAND --option`` the README mentions exists (commands and options of the CLI).
* The Quick start is two commands sharing one editable install, the second being CI's.
"""
from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import click
import pytest

from mrstereo.cli import entry, main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
MARK = "<!-- readme-test:"


def _shell_blocks(text: str, *, marked: bool) -> list[list[str]]:
    """Commands of the ```sh blocks (continuation lines joined, comments dropped)."""
    blocks = []
    for match in re.finditer(r"(<!--[^\n]*-->\n)?```sh\n(.*?)```", text, re.S):
        if marked != bool(match.group(1) and match.group(1).startswith(MARK)):
            continue
        lines, current = [], ""
        for raw in match.group(2).splitlines():
            current += raw.rstrip("\\").strip() + " "
            if not raw.endswith("\\"):
                command = current.split(" #")[0].strip()
                if command:
                    lines.append(command)
                current = ""
        blocks.append(lines)
    return blocks


def test_the_readme_marks_runnable_examples():
    blocks = _shell_blocks(README, marked=True)
    assert blocks and all(line.startswith("mrstereo ") for block in blocks for line in block)
    assert sum(len(block) for block in blocks) >= 5


@pytest.fixture(scope="module")
def demo_like(synthetic_dataset, tmp_path_factory):
    """The parts of a demo output the examples read: data/, map/map.yaml, calibration/stereo.yaml."""
    root = tmp_path_factory.mktemp("readme")
    demo = root / "mrstereo-demo"
    (demo / "calibration").mkdir(parents=True)
    (demo / "data").symlink_to(synthetic_dataset(seed=0, n_frames=3))
    shutil.copy(demo / "data" / "calibration.yaml", demo / "calibration" / "stereo.yaml")
    assert entry(["map", str(demo / "data"), "-o", str(demo / "map"), "--quiet"]) == 0
    return root


def _outputs(argv: list[str]) -> list[str]:
    return [argv[k + 1] for k, arg in enumerate(argv[:-1])
            if arg in ("-o", "--out", "--plot", "--json", "--markdown")]


@pytest.mark.parametrize("line", [line for block in _shell_blocks(README, marked=True) for line in block])
def test_marked_readme_example_runs(line, demo_like, monkeypatch, capsys):
    monkeypatch.chdir(demo_like)
    argv = shlex.split(line)
    assert argv[0] == "mrstereo"
    code = entry(argv[1:])
    assert code == 0, capsys.readouterr().err
    for out in _outputs(argv[1:]):
        assert Path(out).exists(), out


def _mentioned_commands(text: str) -> list[list[str]]:
    """Every `mrstereo ...` in inline code or a shell block, as tokens up to the first pipe / &&."""
    found = re.findall(r"`(mrstereo [^`]+)`", text)
    found += [line for block in _shell_blocks(text, marked=False) + _shell_blocks(text, marked=True)
              for line in block if line.startswith("mrstereo ")]
    plain = [re.sub(r'"?\$\([^)]*\)"?', "ARG", snippet.replace("\\|", "/")) for snippet in found]
    return [shlex.split(re.split(r"&&|\|", snippet)[0]) for snippet in plain]


def test_every_command_and_option_in_the_readme_exists():
    for tokens in _mentioned_commands(README):
        command, rest = main, tokens[1:]
        while isinstance(command, click.Group) and rest and rest[0] in command.commands:
            command, rest = command.commands[rest[0]], rest[1:]
        assert command is not main, f"no such command: {' '.join(tokens)}"
        options = {opt for param in command.params for opt in param.opts + param.secondary_opts}
        for token in rest:
            name = token.strip("[]").split("=")[0]
            if name.startswith("--"):
                assert name in options, f"{' '.join(tokens)}: {name} is not an option of {command.name}"


def test_quick_start_is_two_commands_on_one_editable_install():
    section = README.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    commands = [line for block in _shell_blocks(section, marked=False) for line in block]
    install = 'python3 -m pip install -e ".[test]"'
    assert commands == [f"{install} && mrstereo demo --out mrstereo-demo", f"{install} && python3 -m pytest -q"]
    ci = (ROOT / ".ci" / "run").read_text()
    assert f"{install} && python3 -m pytest -q" in ci.replace("-q -e", "-e")
