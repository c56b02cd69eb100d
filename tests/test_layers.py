"""The import graph of `dpm`: no cycle, and every import goes down the layers of docs/design.md.

Read from the source (no module is imported), counting imports inside functions too, so a
lazy import cannot hide a cycle: an import made lazy to save start-up time is fine, one made
lazy to break a circle is not.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1] / "dpm"

# Lowest first; a module may import its own layer and those below (docs/design.md).
LAYERS = {
    "core": ("dpm.errors", "dpm.clock", "dpm.collector", "dpm._lean_numba", "dpm.stopwatch",
             "dpm.compiling", "dpm.io", "dpm.metrics", "dpm.camera", "dpm.obj", "dpm.options",
             "dpm.scene", "dpm.mitsuba_xml", "dpm.parallel", "dpm.filters", "dpm.textures"),
    "tracer": ("dpm.tracer",),
    "density": ("dpm.density",),
    "nn": ("dpm.nn", "dpm.caustic", "dpm.nn.features", "dpm.nn.fused", "dpm.nn.infer",
           "dpm.nn.model", "dpm.nn.shape_net", "dpm.nn.weights"),
    "estimators": ("dpm.estimators",),
    "methods": ("dpm.denoise", "dpm.methods"),
    "render": ("dpm.renderer",),
    "training": ("dpm.data", "dpm.nn.config", "dpm.nn.losses", "dpm.nn.run_folder",
                 "dpm.nn.sampler", "dpm.nn.shape_training", "dpm.nn.caustic_training",
                 "dpm.nn.sharding", "dpm.nn.train"),
    "validation": ("dpm.validation",),
    "cli": ("dpm", "dpm.cli"),
}  # fmt: skip


def modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its own name)."""
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def layer(name: str) -> int:
    """Index in LAYERS of the longest prefix of `name` listed there (the package `dpm` itself
    is no prefix: each module is placed)."""
    best, found = -1, None
    for i, prefixes in enumerate(LAYERS.values()):
        for prefix in prefixes:
            within = name.startswith(prefix + ".") and prefix != "dpm"
            if (name == prefix or within) and len(prefix) > best:
                best, found = len(prefix), i
    assert found is not None, f"{name} is in no layer of LAYERS"
    return found


def imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its source, and the packages
    those run first (bar its own ancestors, which are already importing)."""
    graph = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for target in targets:
                while target and target not in mods:
                    target = target.rpartition(".")[0]
                if not target or target == name:
                    continue
                parts = target.split(".")
                for i in range(1, len(parts) + 1):  # the target and the packages above it
                    step = ".".join(parts[:i])
                    if step in mods and step != name and not name.startswith(step + "."):
                        found.add(step)
        graph[name] = found
    return graph


def cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of the graph (as a list of modules), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_import_cycle():
    """No module of dpm imports, even lazily, one that imports it back."""
    found = cycle(imports(modules()))
    assert found is None, "import cycle: " + " -> ".join(found)


def test_imports_go_down_the_layers():
    """Every import goes to the module's own layer or one below."""
    graph = imports(modules())
    names = list(LAYERS)
    upward = [
        f"{m} ({names[layer(m)]}) -> {t} ({names[layer(t)]})"
        for m, targets in graph.items()
        for t in targets
        if layer(t) > layer(m)
    ]
    assert not upward, "imports up the layers:\n" + "\n".join(sorted(upward))


def test_the_check_finds_a_cycle():
    """The cycle finder is not blind: a two-module circle is reported."""
    assert cycle({"a": {"b"}, "b": {"a"}}) == ["a", "b", "a"]
    assert cycle({"a": {"b"}, "b": set()}) is None


@pytest.mark.parametrize("name", sorted(modules()))
def test_every_module_has_a_layer(name):
    """A new module must be placed in LAYERS (and in docs/design.md)."""
    layer(name)
