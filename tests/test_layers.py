"""Imports run one way (STYLE.md "Layout", docs/ARCHITECTURE.md): no upward import, no cycle.

Imports are read with ``ast`` from every module of the project, function-local imports
included (a lazy import is still a dependency).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LAYERS: tuple[tuple[str, ...], ...] = (
    ("coop_gym.compiled",),
    ("coop_gym.model", "estimator"),
    ("coop_gym",),
    ("estimator.experiment", "agents"),
    ("train", "scripts", "bench"),
)
"""The layer order, lowest first: a module may import its own group and any lower layer.

Groups of one layer (e.g. the model and the filters) may not import each other.
``coop_gym.model`` is its own group below the rest of ``coop_gym`` (the envs, registration, cli).
"""

KNOWN_CYCLES: frozenset[frozenset[str]] = frozenset()
"""Import cycles tolerated for now (none: every cycle fails the test)."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules() -> dict[str, Path]:
    groups = {prefix.split(".")[0] for layer in LAYERS for prefix in layer}
    modules = {}
    for group in sorted(groups):
        if (ROOT / f"{group}.py").is_file():
            modules[group] = ROOT / f"{group}.py"
        for path in sorted((ROOT / group).rglob("*.py")) if (ROOT / group).is_dir() else []:
            modules[_module_name(path)] = path
    return modules


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Project modules imported anywhere in ``path`` (``from package import module`` counts the module)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            submodules = [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
            targets = submodules or [base]
        else:
            continue
        found.update(t for t in targets if t in modules and t != name)
    return found


def group_of(name: str) -> tuple[int, str]:
    best: tuple[int, str] | None = None
    for level, layer in enumerate(LAYERS):
        for prefix in layer:
            if (name == prefix or name.startswith(prefix + ".")) and (best is None or len(prefix) > len(best[1])):
                best = (level, prefix)
    assert best is not None, f"{name} is in no layer: add it to LAYERS"
    return best


def import_graph() -> dict[str, set[str]]:
    modules = project_modules()
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def test_every_import_runs_down_the_layers() -> None:
    bad = []
    for name, imported in sorted(import_graph().items()):
        level, group = group_of(name)
        for target in sorted(imported):
            target_level, target_group = group_of(target)
            if target_level > level or (target_level == level and target_group != group):
                bad.append(f"{name} ({group}, layer {level}) imports {target} ({target_group}, layer {target_level})")
    assert not bad, "upward or sideways imports:\n" + "\n".join(bad)


def _strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """Tarjan's algorithm (iterative); components of more than one module, or with a self-loop."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = set()
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.add(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        components.append(component)
            elif child not in index:
                index[child] = low[child] = counter
                counter += 1
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(sorted(graph[child]))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return components


def test_no_import_cycles_except_the_known_ones() -> None:
    cycles = [frozenset(c) for c in _strongly_connected(import_graph())]
    unexpected = [sorted(c) for c in cycles if c not in KNOWN_CYCLES]
    assert not unexpected, f"import cycles: {unexpected}"
    fixed = [sorted(c) for c in KNOWN_CYCLES if c not in cycles]
    assert not fixed, f"these cycles are gone: remove them from KNOWN_CYCLES: {fixed}"


def test_the_checker_sees_cycles_and_upward_imports() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert [sorted(c) for c in _strongly_connected(graph)] == [["a", "b", "c"]]
    assert group_of("coop_gym.model.dynamics") == (1, "coop_gym.model")
    assert group_of("coop_gym.envs.core") == (2, "coop_gym")
    assert group_of("estimator.identify") == (1, "estimator")
    assert group_of("estimator.experiment.protocol") == (3, "estimator.experiment")
    assert group_of("coop_gym.compiled.rng") == (0, "coop_gym.compiled")


def test_estimator_filters_import_nothing_of_coop_gym() -> None:
    graph = import_graph()

    def leaked(target: str) -> bool:
        return target.startswith("coop_gym") and not target.startswith("coop_gym.compiled")

    filters = [name for name in graph if name.startswith("estimator") and not name.startswith("estimator.experiment")]
    leaks = {name: sorted(t for t in graph[name] if leaked(t)) for name in filters}
    assert filters and not {k: v for k, v in leaks.items() if v}
