"""The package's shape: no import cycle between modules, and data flows forward through the stages.

Read from the source (``ast``; imports inside functions count too), nothing is imported.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

# Bottom to top: a module may import its own layer or a lower one, never a higher one.
LAYERS = [
    {"mrstereo", "_checks", "_interrupt", "_limits", "profiling", "transforms", "io", "viz"},
    {"camera"},
    {"calibration", "matching"},
    {"rejection"},
    {"geometry"},
    {"mapping"},
    {"odometry"},
    {"recordings"},
    {"pipeline", "_warmup"},
    {"world", "evaluation"},
    {"demo"},
    {"cli", "__main__"},
]


def _modules() -> dict[str, Path]:
    out = {}
    for path in (SRC / "mrstereo").rglob("*.py"):
        parts = path.relative_to(SRC).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package modules that ``name`` imports (``from pkg import sub`` counts as ``pkg.sub``)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            candidates = [target] + [f"{target}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            candidates = [alias.name for alias in node.names]
        else:
            continue
        for candidate in candidates:
            while candidate and candidate not in modules:
                candidate = candidate.rpartition(".")[0]
            # a package's __init__ re-exporting its own submodules is not a dependency of logic
            if candidate and candidate != name and not name.startswith(candidate + "."):
                found.add(candidate)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _layer(module: str) -> int:
    part = module.split(".")[1] if "." in module else module
    return next(k for k, layer in enumerate(LAYERS) if part in layer)


def test_no_import_cycle():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_every_module_has_a_layer_and_imports_only_downward():
    upward = [f"{a} -> {b}" for a, targets in _graph().items() for b in targets if _layer(b) > _layer(a)]
    assert not upward, "imports from a higher layer: " + ", ".join(sorted(upward))


def test_the_check_sees_a_cycle_and_an_upward_import(tmp_path, monkeypatch):
    pkg = tmp_path / "mrstereo"
    (pkg / "camera").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "camera" / "__init__.py").write_text("from .a import x\n")
    (pkg / "camera" / "a.py").write_text("from .b import y\nx = 1\n")
    (pkg / "camera" / "b.py").write_text("def f():\n    from .a import x\n    from ..pipeline import run\ny = 2\n")
    (pkg / "pipeline.py").write_text("")
    monkeypatch.setattr(sys.modules[__name__], "SRC", tmp_path)
    graph = _graph()
    assert "mrstereo.camera.b" in graph["mrstereo.camera.a"] and "mrstereo.camera.a" in graph["mrstereo.camera.b"]
    assert _layer("mrstereo.pipeline") > _layer("mrstereo.camera.b")
    assert "mrstereo.pipeline" in graph["mrstereo.camera.b"]
