"""The package's shape: no import cycle between modules, and data flows forward through the stages.

Read from the source (``ast``; imports inside functions count too), nothing is imported.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

# Bottom to top: a module may import its own layer or a lower one, never a higher one.
LAYERS = [
    {"mrstereo", "_checks", "_executor", "_interrupt", "_limits", "profiling", "transforms", "io", "viz"},
    {"camera"},
    {"calibration", "matching"},
    {"rejection"},
    {"geometry"},
    {"mapping"},
    {"odometry"},
    {"recordings"},
    {"evaluation"},
    {"pipeline", "_warmup"},
    {"world"},
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


# The per-frame chain match -> reject -> 3-D -> scan -> grid is composed in one place: pipeline/mapper.py
# (the pair half, match -> reject -> 3-D, in geometry/pair.py). A module that runs a pair through the chain
# must not also put points into a grid, and within pipeline/ only the mapper runs pairs through the chain.
# Visual odometry of frames is the mapper's too: outside the odometry stage only the mapper runs a tracker.
_PAIR_CHAIN = re.compile(r"\b(obstacles_from_pair|scan_from_pair|observe_pair)\(")
_STAGES = re.compile(r"\b(compute_disparity|reject_uniform|detect_obstacles)\(")
_TRACKER = re.compile(r"\b(StereoOdometry|visual_odometry)\(")
_GRID_UPDATE = re.compile(r"\b(fuse_step|add_observation|fuse|view_cells)\(|\.update\(\w*obstacle|\.apply\(")
_MAPPER = "pipeline/mapper.py"
_PAIR = "geometry/pair.py"


def _chain_modules(src_root: Path) -> dict[str, set[str]]:
    """``{module path: {"pair", "stages", "grid"}}``: which parts of the chain each module calls."""
    found = {}
    for path in (src_root / "mrstereo").rglob("*.py"):
        text = "\n".join(line.split("#")[0] for line in path.read_text(encoding="utf-8").splitlines())
        text = re.sub(r"def \w+\(", "def (", text)                  # definitions are not calls
        kinds = {kind for kind, pattern in (("pair", _PAIR_CHAIN), ("grid", _GRID_UPDATE), ("tracker", _TRACKER))
                 if pattern.search(text)}
        if len(set(_STAGES.findall(text))) >= 2:                      # two stages called one after the other
            kinds.add("stages")
        found[path.relative_to(src_root / "mrstereo").as_posix()] = kinds
    return found


def _chain_violations(src_root: Path) -> list[str]:
    bad = []
    for module, kinds in _chain_modules(src_root).items():
        if {"pair", "grid"} <= kinds and module != _MAPPER:
            bad.append(f"{module} runs pairs through the chain and updates a grid (only {_MAPPER} may)")
        if module.startswith("pipeline/") and "pair" in kinds and module not in (_MAPPER, _PAIR):
            bad.append(f"{module} runs pairs through the chain (in pipeline/ only {_MAPPER} may)")
        if "stages" in kinds and module.startswith(("pipeline/", "geometry/", "mapping/")) and module != _PAIR:
            bad.append(f"{module} composes match, reject and 3-D itself (only {_PAIR} may)")
        if "tracker" in kinds and not module.startswith("odometry/") and module != _MAPPER:
            bad.append(f"{module} runs visual odometry itself (only {_MAPPER} may)")
    return bad


def test_the_per_frame_chain_is_composed_in_the_mapper_only():
    assert not _chain_violations(SRC), "; ".join(_chain_violations(SRC))
    kinds = _chain_modules(SRC)
    assert {"pair", "grid", "tracker"} <= kinds[_MAPPER] and "stages" in kinds[_PAIR]


def test_the_chain_check_sees_a_second_composition(tmp_path):
    pkg = tmp_path / "mrstereo" / "pipeline"
    pkg.mkdir(parents=True)
    (pkg / "mapper.py").write_text("a = scan_from_pair(l, r)\nfuse_step(grid, a)\nvo = StereoOdometry(s)\n")
    (tmp_path / "mrstereo" / "geometry").mkdir()
    (tmp_path / "mrstereo" / "geometry" / "pair.py").write_text("d = compute_disparity(l, r)\n")
    assert not _chain_violations(tmp_path)
    (pkg / "live.py").write_text("p = obstacles_from_pair(l, r)  \nadd_observation(grid, p)\n")
    (pkg / "batch.py").write_text("x = scan_from_pair(l, r)\n")
    (pkg / "run.py").write_text("d = compute_disparity(l, r)\nrej = reject_uniform(d, l)\n")
    (pkg / "odometry.py").write_text("result = visual_odometry(pairs, stereo)\n")
    found = " ".join(_chain_violations(tmp_path))
    assert "live.py runs pairs through the chain and updates a grid" in found
    assert "batch.py runs pairs" in found and "run.py composes" in found
    assert "odometry.py runs visual odometry itself" in found
