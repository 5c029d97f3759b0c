"""The package's layers, read from its imports (every import, also those inside functions): no
module imports one of a higher layer, the imports form no circle, and none imports PyTorch.

Layers, bottom up (docs/DESIGN.md §1): a module may import its own layer and those below.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "motiongan_jax"
LAYERS = (
    ("atomic", "cache", "config"),  # leaves: import nothing of the package, not even each other
    ("motion",),
    ("data", "viz"),
    ("nn",),
    ("model",),
    ("train",),
    ("generate",),
    ("analysis",),
    ("evaluation",),
    ("cli",),
    ("demo",),
)
RANK = {part: i for i, layer in enumerate(LAYERS) for part in layer}


def _module_name(path: Path, package: Path) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """module -> the package's modules it imports (`from a.b import c` names a.b.c when c is a
    module, else a.b)."""
    modules = {_module_name(p, package): p for p in package.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        out = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    full = f"{node.module}.{alias.name}"
                    out.add(full if full in modules else node.module)
            elif isinstance(node, ast.Import):
                out.update(alias.name for alias in node.names)
        graph[name] = {m for m in out if m in modules and m != name}
    return graph


def layer_of(module: str) -> str:
    """The layer a module belongs to: its subpackage, or the top-level module itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{a} -> {b}" for a, outs in graph.items() for b in outs
                  if layer_of(b) in RANK and RANK[layer_of(b)] > RANK[layer_of(a)]
                  or layer_of(b) in LAYERS[0] and layer_of(a) in LAYERS[0] and layer_of(a) != layer_of(b))


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every circle found by a depth-first search (each reported once, from where it closes)."""
    found, state, stack = [], {}, []

    def visit(u):
        state[u] = "open"
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == "open":
                found.append(stack[stack.index(v):] + [v])
            elif v not in state:
                visit(v)
        stack.pop()
        state[u] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m)
    return found


def foreign_imports(top: str, package: Path = PACKAGE) -> list[str]:
    """The package's modules that import `top` (or a module under it), anywhere in the file."""
    found = set()
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0
                     else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            if any(n == top or n.startswith(top + ".") for n in names):
                found.add(_module_name(path, package))
    return sorted(found)


def test_the_package_never_imports_torch():
    # PyTorch is the benchmarks' optional dependency (pyproject's `bench` extra), never the package's
    assert foreign_imports("torch") == []


def test_the_foreign_import_check_finds_a_lazy_one(tmp_path):
    root = tmp_path / "motiongan_jax" / "nn"
    root.mkdir(parents=True)
    (root / "a.py").write_text("def f():\n    import torch.nn.functional as F\n")
    (root / "b.py").write_text("import torchvision\n")
    assert foreign_imports("torch", root.parent) == ["motiongan_jax.nn.a"]


def test_every_part_of_the_package_has_a_layer():
    parts = {layer_of(m) for m in import_graph()} - {"motiongan_jax"}
    assert parts == set(RANK), (sorted(parts - set(RANK)), sorted(set(RANK) - parts))


def test_no_import_points_up_a_layer():
    assert upward_imports(import_graph()) == []


def test_the_imports_form_no_circle():
    assert circles(import_graph()) == []


@pytest.mark.parametrize("files, bad", [
    ({"train/step.py": "from motiongan_jax.generate import walk\n", "generate/walk.py": ""},
     ["motiongan_jax.train.step -> motiongan_jax.generate.walk"]),
    ({"config.py": "from motiongan_jax import atomic\n", "atomic.py": ""},
     ["motiongan_jax.config -> motiongan_jax.atomic"]),
    ({"data/a.py": "def f():\n    from motiongan_jax.model import build\n", "model/build.py": ""},
     ["motiongan_jax.data.a -> motiongan_jax.model.build"]),
])
def test_the_checks_find_what_they_look_for(tmp_path, files, bad):
    # a lazy import inside a function counts; a leaf importing another leaf is refused too
    root = tmp_path / "motiongan_jax"
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    assert upward_imports(import_graph(root)) == bad


def test_a_circle_is_found(tmp_path):
    root = tmp_path / "motiongan_jax" / "data"
    root.mkdir(parents=True)
    (root / "a.py").write_text("from motiongan_jax.data import b\n")
    (root / "b.py").write_text("def f():\n    from motiongan_jax.data import a\n")
    assert circles(import_graph(root.parent)) == [["motiongan_jax.data.a", "motiongan_jax.data.b",
                                                   "motiongan_jax.data.a"]]
