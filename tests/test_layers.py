"""The package's import structure: layers only import downwards, and no module circle.

Every ``import`` in ``src/pirl`` counts, at module level or inside a function: a lazy import
still ties two modules together. Within one layer (one subpackage) modules may import each
other, but never in a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "pirl"

# The layers, lowest first; a module may import its own layer and the layers below it. Keep in
# step with docs/architecture.md.
LAYERS = (
    ("pirl", "pirl._atomic", "pirl._numba_cache", "pirl._paths", "pirl._torch"),  # the root:
    # atomic writes, cache folder, numba, torch's process settings, env registration
    ("pirl.config",),  # the action grid, the errors and every settings section
    ("pirl.world",),  # grid, scenarios, footprints, rules, metrics, planning queries
    ("pirl.env",),  # Gymnasium / SB3 environments over the world
    ("pirl.advice",),  # prompts, advisors, parsing, cache, budget
    ("pirl.pare",),  # reward shaping with advice
    ("pirl.agents",),  # policies, training, imitation, loading
    ("pirl.physics",),  # the grid policy flown by a simulated quadrotor
    ("pirl.evaluate",),  # episodes run and summarised, advice scored, executors (Ray)
    ("pirl.missions",),  # survey missions: written, read back, flown; site checks
    ("pirl.report",),  # tables, figures and the reproduction report
    ("pirl.reproduce",),  # the reproduction: its plan, training jobs and sequence
    ("pirl.cli", "pirl.terminal", "pirl.__main__"),  # the command line and its terminal side
)
# Imports that break the layering today, as (importer, imported): each is a known debt with an
# owner. Remove a line once it is paid; the test fails on a line that no longer applies.
ALLOWED: frozenset[tuple[str, str]] = frozenset()


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def layer(module: str) -> int:
    """Index in LAYERS of the longest prefix that names ``module``'s layer."""
    best, best_len = -1, -1
    for rank, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = rank, len(prefix)
    if best < 0:
        raise AssertionError(f"{module} is in no layer; add it to LAYERS")
    return best


def resolve(importer: str, node: ast.ImportFrom | ast.Import) -> list[str]:
    """The pirl modules an import statement loads (a name that is a module counts as one)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name == "pirl" or a.name.startswith("pirl.")]
    base = node.module or ""
    if node.level:
        pkg = importer.split(".")
        if MODULES[importer].name != "__init__.py":
            pkg = pkg[:-1]
        pkg = pkg[: len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([base] if base else []))
    if not (base == "pirl" or base.startswith("pirl.")):
        return []
    out = []
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        out.append(sub if sub in MODULES else base)
    return out


def import_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import | ast.ImportFrom):
                edges.update(m for m in resolve(name, node) if m != name)
        graph[name] = edges
    return graph


GRAPH = import_graph()


def test_every_module_has_a_layer() -> None:
    for name in MODULES:
        layer(name)


def test_imports_only_go_down_the_layers() -> None:
    upward = sorted(
        (src, dst)
        for src, edges in GRAPH.items()
        for dst in edges
        if layer(dst) > layer(src) and (src, dst) not in ALLOWED
    )
    names = [f"{src} -> {dst} ({LAYERS[layer(src)][0]} may not import {LAYERS[layer(dst)][0]})"
             for src, dst in upward]  # fmt: skip
    assert not names, "upward imports:\n" + "\n".join(names)


def test_allowed_exceptions_still_apply() -> None:
    stale = [pair for pair in ALLOWED if pair[1] not in GRAPH.get(pair[0], set())]
    assert not stale, f"remove these from ALLOWED, they are gone: {stale}"


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle (a list of modules, first repeated last), or None."""
    state: dict[str, int] = {}  # 1 = on the current path, 2 = done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_import_circle() -> None:
    cycle = find_cycle(GRAPH)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


@pytest.mark.parametrize(
    ("graph", "circle"),
    [
        ({"a": {"b"}, "b": {"c"}, "c": set()}, False),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, True),
        ({"a": {"b", "c"}, "b": {"c"}, "c": {"b"}}, True),
    ],
)
def test_cycle_finder(graph: dict[str, set[str]], circle: bool) -> None:
    assert (find_cycle(graph) is not None) is circle


def test_the_walker_sees_lazy_imports() -> None:
    # jobs imports train_one inside a function; the graph must still hold that edge.
    assert "pirl.agents.runs" in GRAPH["pirl.reproduce.jobs"]
    assert "pirl.world.dynamics" in GRAPH["pirl.env.core"]
