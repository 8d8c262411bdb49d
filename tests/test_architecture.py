"""The packages' import structure (docs/api.md, "Architecture"): layers import downwards only, no import cycles, no
imports hidden inside functions except the documented ones, no Gymnasium below the env layer, and every import of
ours through the one namespace ``bboxtune`` (module names here are written without that prefix).

Run as a script (``python tests/test_architecture.py [ROOT]``) it prints the counts for any checkout."""

from __future__ import annotations

import ast
import sys
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("filters", "envs", "agents")  # importable as bboxtune.filters, ... (pyproject's package-dir)
NAMESPACE = "bboxtune"
# the layers, lowest first: a module imports only modules of its own layer or a lower one
LAYERS = (("filters",), ("envs.data",), ("envs.video",), ("envs.episodes",),
          ("envs", "envs.track_env", "envs.tune_env", "envs.retune_env", "envs.vector", "envs.render"),
          ("agents.readers", "agents.cli", "agents.splits", "agents.episodes"), ("agents.policies",), ("agents.training",),
          ("agents.evaluation",), ("agents.smoothing", "agents", "agents.reproduce"), ("agents.tracking",),
          ("agents.commands",))
# imports inside functions that stay, with the reason: an optional extra (ray, tensorboard; filterpy of the test
# extra), or torch / SB3 deferred until a model is loaded (agents.smoothing.tuner is imported by every ``import
# bboxtune.agents``;
# importing torch there costs seconds)
DEFERRED = {("agents.training.sweep", "ray"), ("agents.commands.sweep", "ray"), ("agents.training.run_checks", "tensorboard"),
            ("agents.commands.bench_filters", "filterpy"), ("agents.smoothing.tuner", "stable_baselines3"),
            ("agents.smoothing.tuner", "agents.training.runs"), ("agents.smoothing.tuner", "agents.training.run_files")}
NO_GYMNASIUM = ("filters", "envs.data", "envs.video", "envs.episodes")


@dataclass
class ImportGraph:
    modules: dict[str, Path]
    edges: dict[str, set[str]] = field(default_factory=dict)  # module-level imports between our modules
    deferred: list[tuple[str, str, str]] = field(default_factory=list)  # (module, function, imported name)
    deferred_edges: dict[str, set[str]] = field(default_factory=dict)  # what those import, of ours
    external: dict[str, set[str]] = field(default_factory=dict)  # top-level names of third-party imports
    bare: list[tuple[str, str]] = field(default_factory=list)  # (module, name): ours imported without the namespace


def _name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _short(name: str) -> str:
    """``bboxtune.envs.data`` -> ``envs.data``; any other name as it is."""
    return name.removeprefix(NAMESPACE + ".")


def import_graph(root: Path = REPO) -> ImportGraph:
    """Every import statement of the packages under ``root``, resolved to our modules where it names one."""
    modules = {_name(root, p): p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))}
    graph = ImportGraph(modules)

    def ours(name: str) -> str | None:
        parts = name.split(".")
        while parts and ".".join(parts) not in modules:
            parts.pop()
        return ".".join(parts) if parts else None

    for mod, path in modules.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        in_function = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                       for n in ast.walk(f) if n is not f}
        owner = {id(n): f.name for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(f)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                written = [a.name for a in node.names]
                names = [_short(n) for n in written]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                written = [base]
                subs = [_short(f"{base}.{a.name}") for a in node.names]
                names = subs if all(s in modules for s in subs) else [_short(base)]
            else:
                continue
            graph.bare.extend((mod, n) for n in written if not getattr(node, "level", 0) and n.split(".")[0] in PACKAGES)
            hidden = id(node) in in_function
            for name in names:
                target = ours(name)
                if hidden:
                    graph.deferred.append((mod, owner[id(node)], name))
                    if target and target != mod:
                        graph.deferred_edges.setdefault(mod, set()).add(target)
                elif target is None:
                    graph.external.setdefault(mod, set()).add(name.split(".")[0])
                elif target != mod:
                    graph.edges.setdefault(mod, set()).add(target)
    return graph


def layer(module: str) -> int:
    """The layer of ``module``: that of the longest prefix in :data:`LAYERS` it starts with (-1: none)."""
    matches = [(len(p), i) for i, prefixes in enumerate(LAYERS) for p in prefixes
               if module == p or module.startswith(p + ".")]
    return max(matches)[1] if matches else -1


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v), on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _all_edges(graph: ImportGraph) -> dict[str, set[str]]:
    return {m: graph.edges.get(m, set()) | graph.deferred_edges.get(m, set()) for m in graph.modules}


def upward(graph: ImportGraph) -> list[tuple[str, str]]:
    """Imports (module-level or in a function) of a module of a higher layer."""
    return sorted((a, b) for a, targets in _all_edges(graph).items() for b in targets if layer(b) > layer(a))


GRAPH = import_graph()


def test_every_module_has_a_layer() -> None:
    assert [m for m in GRAPH.modules if layer(m) < 0] == []


def test_no_import_cycles_even_through_imports_inside_functions() -> None:
    assert cycles(_all_edges(GRAPH)) == []


def test_layers_import_downwards_only() -> None:
    assert upward(GRAPH) == []


def test_imports_inside_functions_are_only_the_documented_deferred_ones() -> None:
    extra = [(m, f, n) for m, f, n in GRAPH.deferred if (m, n.split(".")[0]) not in DEFERRED and (m, n) not in DEFERRED]
    assert extra == []


def test_every_import_of_ours_goes_through_the_namespace() -> None:
    """``import filters`` would find the source folder from a checkout only, and a second copy of the module."""
    assert GRAPH.bare == []


def test_tests_and_scripts_import_the_namespace_too() -> None:
    bare = []
    for path in sorted([*(REPO / "tests").rglob("*.py"), *(REPO / "scripts").glob("*.py"), *(REPO / "docs").rglob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            written = ([a.name for a in node.names] if isinstance(node, ast.Import)
                       else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            bare += [(path.relative_to(REPO).as_posix(), n) for n in written if n.split(".")[0] in PACKAGES]
    assert bare == []


def test_no_gymnasium_below_the_env_layer() -> None:
    users = sorted(m for m, names in GRAPH.external.items() if "gymnasium" in names
                   and any(m == p or m.startswith(p + ".") for p in NO_GYMNASIUM))
    assert users == []


def test_the_checks_catch_a_cycle_and_an_upward_import() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    fake = ImportGraph({"filters.x": Path(), "agents.y": Path()}, edges={"filters.x": {"agents.y"}})
    assert upward(fake) == [("filters.x", "agents.y")]
    assert layer("envs.tune_env") > layer("envs.episodes.sources") > layer("envs.video.detectors") > layer("envs.data.otb")


if __name__ == "__main__":
    root = Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else REPO
    g = import_graph(root)
    print(f"{root}: {len(g.modules)} modules, {sum(map(len, g.edges.values()))} module-level imports between them")
    print(f"import cycles (module-level only): {len(cycles(g.edges))} {cycles(g.edges)}")
    print(f"import cycles (with imports inside functions): {len(cycles(_all_edges(g)))} {cycles(_all_edges(g))}")
    print(f"upward imports: {len(upward(g))} {upward(g)}")
    print(f"imports inside functions: {len(g.deferred)}")
    for m, f, n in g.deferred:
        print(f"  {m}.{f}: {n}")
