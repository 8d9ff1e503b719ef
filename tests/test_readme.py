"""The README and docs/*.md agree with the code, and the README's examples run as written.

* Shell blocks of the README marked ``<!-- readme-test: ... -->`` run line by line, in order, in a
  folder that holds what ``mrstereo demo --out mrstereo-demo`` writes and these examples read (a
  small corridor dataset, its map and its calibration), and must write the files they name; its
  Python blocks run there too.
* Every ``mrstereo COMMAND --option`` the README and the docs mention exists, every output is
  ``-o/--out``, and every command's one-line help is a whole sentence.
* Every ``from mrstereo... import`` of their Python blocks and every dotted ``mrstereo.x.y`` name
  resolves; every relative link points to a file and, with ``#anchor``, to one of its headings;
  every module docstring links docs/conventions.md.
* The Quick start is two commands sharing one editable install, the second being CI's.
"""
from __future__ import annotations

import importlib
import re
import shlex
import shutil
from pathlib import Path

import click
import pytest

from mrstereo.cli import entry, main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
DOCS = {path: path.read_text(encoding="utf-8") for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]}
MARK = "<!-- readme-test:"


def _shell_blocks(text: str, *, marked: bool) -> list[list[str]]:
    """Commands of the ```sh blocks (continuation lines joined, comments dropped)."""
    blocks = []
    for match in re.finditer(r"(<!--[^\n]*-->\n)?```sh\n(.*?)```", text, re.S):
        if marked != bool(match.group(1) and match.group(1).startswith(MARK)):
            continue
        blocks.append(_commands(match.group(2)))
    return blocks


def _commands(block: str) -> list[str]:
    lines, current = [], ""
    for raw in block.splitlines():
        current += raw.rstrip().rstrip("\\").strip() + " "
        if not raw.rstrip().endswith("\\"):
            command = current.split(" #")[0].strip()
            if command:
                lines.append(command)
            current = ""
    return lines


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
    argv = shlex.split(_with_sample_paths(line))
    assert argv[0] == "mrstereo"
    code = entry(argv[1:])
    assert code == 0, capsys.readouterr().err
    for out in _outputs(argv[1:]):
        assert Path(out).exists(), out


def _with_sample_paths(line: str) -> str:
    """``$(mrstereo data path NAME)`` replaced by the sample's folder, as the shell would (skip without it)."""
    from mrstereo.recordings import samples

    def folder(match):
        name = match.group(1)
        if samples.missing_files(name):
            pytest.skip(f"sample data {name!r} not found: set {samples.ENV_VAR} or run `mrstereo data fetch {name}`")
        return str(samples.local_path(name))
    return re.sub(r"\$\(mrstereo data path ([\w.-]+)\)", folder, line)


def test_the_readme_python_runs(demo_like, monkeypatch, capsys):
    monkeypatch.chdir(demo_like)
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
    assert "(" in capsys.readouterr().out


def _mentioned_commands(text: str) -> list[list[str]]:
    """Every `mrstereo ...` in inline code or a fenced block, as tokens up to the first pipe, ``&&`` or ``;``."""
    found = re.findall(r"`(mrstereo [^`]+)`", text)
    found += [line for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S) for line in _commands(block)
              if line.startswith("mrstereo ")]
    plain = [re.sub(r"\$\([^)]*\)", "ARG", snippet.replace("\\|", "/")) for snippet in found]
    return [shlex.split(re.split(r"&&|\||;", snippet)[0]) for snippet in plain]


@pytest.mark.parametrize("doc", sorted(DOCS), ids=lambda path: path.name)
def test_every_command_and_option_in_the_docs_exists(doc):
    mentioned = _mentioned_commands(DOCS[doc])
    assert mentioned or doc.parent.name == "docs"
    for tokens in mentioned:
        command, rest = main, tokens[1:]
        while isinstance(command, click.Group) and rest and rest[0] in command.commands:
            command, rest = command.commands[rest[0]], rest[1:]
        assert command is not main, f"no such command: {' '.join(tokens)}"
        options = {opt for param in command.params for opt in param.opts + param.secondary_opts}
        for token in rest:
            name = token.strip("[]()").split("=")[0]
            if name.startswith("--"):
                assert name in options, f"{' '.join(tokens)}: {name} is not an option of {command.name}"


def _leaf_commands(group=main, prefix="mrstereo"):
    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from _leaf_commands(command, f"{prefix} {name}")
        else:
            yield f"{prefix} {name}", command


def test_every_output_is_dash_o_or_dash_dash_out():
    for name, command in _leaf_commands():
        for param in command.params:
            assert "--output" not in param.opts, f"{name}: --output (the spelling is -o/--out)"
            if "-o" in param.opts or "--out" in param.opts:
                assert sorted(param.opts) == ["--out", "-o"], f"{name}: {param.opts}"


def test_every_help_starts_with_a_whole_sentence():
    """``mrstereo --help`` lists each command with the first sentence of its help, uncut."""
    width = 80 - 6 - max(len(name) for name in main.commands)      # what click's command list leaves
    groups = [("mrstereo", main)]
    groups += [(f"mrstereo {name}", c) for name, c in main.commands.items() if isinstance(c, click.Group)]
    for group_name, group in groups:
        for name, command in group.commands.items():
            short = command.get_short_help_str(limit=width)
            assert short.endswith(".") and not short.endswith("..."), f"{group_name} {name}: {short!r}"


def _python_names(text: str) -> list[str]:
    """``module:name`` of every ``from mrstereo... import`` in the Python blocks and every dotted mrstereo name."""
    found = []
    for block in re.findall(r"```python\n(.*?)```", text, re.S):
        block = re.sub(r"\(\s*([^)]*?)\s*\)", lambda m: m.group(1).replace("\n", " "), block)
        for module, names in re.findall(r"^\s*from (mrstereo[\w.]*) import (.+)$", block, re.M):
            found += [f"{module}:{name.strip().split(' as ')[0]}" for name in names.split("#")[0].split(",")]
    for dotted in re.findall(r"\bmrstereo(?:\.\w+)+", text):
        found.append(dotted)
    return found


def _resolves(name: str) -> bool:
    module, _, attr = name.partition(":")
    parts = module.split(".") + ([attr] if attr else [])
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for part in parts[k:]:
            if part.endswith("_") or not hasattr(obj, part):     # LABEL_*: a family of names
                return part.endswith("_")
            obj = getattr(obj, part)
        return True
    return False


@pytest.mark.parametrize("doc", sorted(DOCS), ids=lambda path: path.name)
def test_every_mrstereo_name_in_the_docs_resolves(doc):
    missing = [name for name in _python_names(DOCS[doc]) if not _resolves(name)]
    assert not missing, f"{doc.name} names what the package does not have: {missing}"


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but hyphens dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    return {_anchor(h) for h in re.findall(r"^#+ (.+)$", text, re.M)}


@pytest.mark.parametrize("doc", sorted(DOCS), ids=lambda path: path.name)
def test_every_relative_link_resolves(doc):
    text = re.sub(r"```.*?```", "", DOCS[doc], flags=re.S)
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = (doc.parent / path).resolve() if path else doc
        assert file.exists(), f"{doc.name}: link to a missing file {target}"
        if anchor:
            assert file.suffix == ".md" and anchor in _anchors(file.read_text(encoding="utf-8")), \
                f"{doc.name}: no heading for {target}"


def test_every_module_docstring_links_the_conventions():
    import ast

    for path in sorted((ROOT / "src" / "mrstereo").rglob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        assert "docs/conventions.md" in doc, f"{path.relative_to(ROOT)}: its docstring does not link the conventions"


def test_quick_start_is_two_commands_on_one_editable_install():
    section = README.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    commands = [line for block in _shell_blocks(section, marked=False) for line in block]
    install, every_extra = 'python3 -m pip install -e ".[test]"', 'python3 -m pip install -e ".[test,viz,scale]"'
    assert commands == [f"{install} && mrstereo demo --out mrstereo-demo", f"{every_extra} && python3 -m pytest -q"]
    ci = (ROOT / ".ci" / "run").read_text()
    assert f"{every_extra} && python3 -m pytest -q" in ci.replace("-q -e", "-e")


def test_the_readme_is_a_page_not_a_report():
    assert len(README.splitlines()) <= 250
    assert '-m "not slow"' in README
