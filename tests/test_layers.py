"""Imports run one way (STYLE.md "Layout", docs/ARCHITECTURE.md): no upward import, no cycle.

Two checks. The packages: each is imported, every module of it, in a fresh interpreter, and
``sys.modules`` must then hold no higher package (a package's ``__init__`` runs at the import of
any of its modules, which an ``ast`` scan of the module does not see). The modules: imports are
read with ``ast`` from every module of the project, function-local imports included (a lazy
import is still a dependency), and each must run down :data:`LAYERS`. ``docs/ARCHITECTURE.md`` is
held to both: its layer and rooms tables are :data:`LAYERS` and :data:`AGENT_ROOMS` with the imports
each group and room really has, and every path of its "Where does a new X go" table exists.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PACKAGES: tuple[str, ...] = ("estimator", "coop_gym", "agents")
"""The packages, lowest first: importing one loads none after it."""

HEAVY = ("torch", "stable_baselines3", "ray")
"""Loaded only from ``agents`` up (STYLE.md "Layout")."""

LAYERS: tuple[tuple[str, ...], ...] = (
    ("estimator.compiled", "estimator.validate"),
    ("coop_gym.model", "estimator"),
    ("coop_gym",),
    ("coop_gym.experiment",),
    ("agents",),
    ("train", "scripts", "bench"),
)
"""The layer order, lowest first: a module may import its own group and any lower layer.

Groups of one layer (e.g. the model and the filters) may not import each other.
``estimator.compiled`` (the kernels' boundary) and ``estimator.validate`` (what counts as a number,
for every validator: the model's parameters and the filters both use it) are groups below the
filters. The ``coop_gym`` package holds three layers: ``coop_gym.model`` below the rest (the envs,
registration, cli, io), and ``coop_gym.experiment`` (the paper's experiment over the model, the envs'
nominal model and the filters) above them, never loaded by them
(:func:`test_importing_coop_gym_loads_not_its_experiment`). ``agents`` sits above the experiment, so
the web app's person role runs the paper's trial design.
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


def _fresh_import(modules: list[str]) -> list[str]:
    """``sys.modules`` of a fresh interpreter after importing ``modules``."""
    code = (
        "import importlib, json, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300, check=True
    )
    return list(json.loads(out.stdout.splitlines()[-1]))


def _modules_of(package: str) -> list[str]:
    return sorted(n for n in project_modules() if n.split(".")[0] == package and not n.endswith("__main__"))


@pytest.mark.parametrize("package", PACKAGES[:-1])
def test_importing_a_package_loads_no_higher_one(package: str) -> None:
    higher = set(PACKAGES[PACKAGES.index(package) + 1 :]) | set(HEAVY)
    loaded = {name.partition(".")[0] for name in _fresh_import(_modules_of(package))}
    assert package in loaded
    assert not loaded & higher, f"importing {package} loads {sorted(loaded & higher)}"


def test_importing_coop_gym_loads_not_its_experiment() -> None:
    """``coop_gym.experiment`` is the top layer of the ``coop_gym`` package, above the envs, and held so at run time.

    It stays inside ``coop_gym`` (the wheel installs no top-level name but the three packages,
    ``scripts/check_installed.py``), so a package test cannot see it: importing every other module of
    ``coop_gym`` in a fresh interpreter must not load it.
    """
    below = [n for n in _modules_of("coop_gym") if group_of(n)[1] != "coop_gym.experiment"]
    loaded = _fresh_import(below)
    assert below and "coop_gym.envs" in loaded
    assert [n for n in loaded if group_of_or_none(n) == "coop_gym.experiment"] == []


def group_of_or_none(name: str) -> str | None:
    """The layer group of a project module, ``None`` for any other module."""
    return group_of(name)[1] if name.partition(".")[0] in PACKAGES else None


def test_the_lowest_layer_loads_no_other_project_module() -> None:
    boundary = [n for n in _modules_of("estimator") if group_of(n)[0] == 0]
    loaded = _fresh_import(boundary)
    project = [n for n in loaded if n.partition(".")[0] in PACKAGES]
    assert boundary and set(boundary) <= set(project)
    assert [n for n in project if n != "estimator" and n not in boundary] == []


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
    assert group_of("estimator.identification.identify") == (1, "estimator")
    assert group_of("coop_gym.experiment.protocol") == (3, "coop_gym.experiment")
    assert group_of("estimator.compiled.rng") == (0, "estimator.compiled")
    assert group_of("estimator.validate") == (0, "estimator.validate")


def test_no_module_imports_a_higher_package() -> None:
    rank = {package: i for i, package in enumerate(PACKAGES)}
    bad = [
        f"{name} imports {target}"
        for name, imported in sorted(import_graph().items())
        if name.split(".")[0] in rank
        for target in sorted(imported)
        if rank.get(target.split(".")[0], -1) > rank[name.split(".")[0]]
    ]
    assert not bad, "imports of a higher package:\n" + "\n".join(bad)


MAX_MODULES_PER_FOLDER = 12
"""STYLE.md "Rooms with names on the doors": a folder of more modules is split into named subpackages."""

CROWDED_FOLDERS: dict[str, int] = {"bench": 17}
"""Folders not yet split, each held to the modules it has now: it may shrink, never grow (``bench/`` holds
scripts, each run by its path, not a package)."""


def test_no_folder_holds_more_than_a_dozen_modules() -> None:
    roots = sorted({prefix.split(".")[0] for layer in LAYERS for prefix in layer})
    folders: dict[str, int] = {}
    for root in roots:
        for path in (ROOT / root).rglob("*.py") if (ROOT / root).is_dir() else []:
            if path.name != "__init__.py":
                folder = path.parent.relative_to(ROOT).as_posix()
                folders[folder] = folders.get(folder, 0) + 1
    assert folders["agents"] <= MAX_MODULES_PER_FOLDER
    crowded = {
        folder: count
        for folder, count in sorted(folders.items())
        if count > CROWDED_FOLDERS.get(folder, MAX_MODULES_PER_FOLDER)
    }
    assert not crowded, f"more than {MAX_MODULES_PER_FOLDER} modules: split into named subpackages: {crowded}"


MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 60
MAX_TRAIN_PY_LINES = 120
"""STYLE.md "Rooms with names on the doors": no module over 600 lines, no function over 60 (its nested
functions included), and ``train.py`` short enough to read top to bottom."""


def test_no_module_or_function_is_too_long() -> None:
    long_modules, long_functions = [], []
    for name, path in project_modules().items():
        source = path.read_text(encoding="utf-8")
        if source.count("\n") > MAX_MODULE_LINES:
            long_modules.append(f"{name}: {source.count(chr(10))} lines")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno is not None:
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long_functions.append(f"{name}.{node.name}: {lines} lines")
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    assert not long_functions, f"functions over {MAX_FUNCTION_LINES} lines: {long_functions}"
    train_lines = (ROOT / "train.py").read_text(encoding="utf-8").count("\n")
    assert train_lines <= MAX_TRAIN_PY_LINES, f"train.py has {train_lines} lines"


def test_the_single_and_the_vector_env_do_not_import_each_other() -> None:
    """What both take from their config (the core, the step's helpers, a frame to draw) is in ``core.py``."""
    graph = import_graph()
    single, vector = "coop_gym.envs.sit_to_stand", "coop_gym.envs.vector"
    assert single not in graph[vector] and vector not in graph[single]
    assert "coop_gym.envs.core" in graph[single] & graph[vector]


AGENT_ROOMS: tuple[str, ...] = (
    "base", "pretrained", "caregivers", "zoo", "evaluate", "ppo", "rl", "tools", "trainer", "tune",
)  # fmt: skip
"""The rooms of ``agents/``, lowest first: a module may import its own room and the rooms before it.
``base`` is the modules directly in ``agents/`` (``base.py``, ``run_folder.py``). A ``__main__`` (what
``python -m`` runs) may import any room: nothing imports it."""


def _room(name: str) -> str:
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and (ROOT / "agents" / parts[1]).is_dir() else "base"


def test_the_rooms_of_agents_import_one_way() -> None:
    rank = {room: i for i, room in enumerate(AGENT_ROOMS)}
    graph = import_graph()
    rooms = {_room(n) for n in graph if n.startswith("agents.")}
    assert rooms <= set(rank), f"rooms of agents/ not in AGENT_ROOMS: {sorted(rooms - set(rank))}"
    bad = [
        f"{name} ({_room(name)}) imports {target} ({_room(target)})"
        for name, imported in sorted(graph.items())
        if name.startswith("agents.") and name != "agents" and not name.endswith("__main__")
        for target in sorted(imported)
        if target.startswith("agents.") and rank[_room(target)] > rank[_room(name)]
    ]
    assert not bad, "imports up the rooms of agents/:\n" + "\n".join(bad)


@pytest.mark.parametrize("room", AGENT_ROOMS[2:-1])
def test_importing_a_room_of_agents_loads_no_higher_one(room: str) -> None:
    """As for the packages, in a fresh interpreter: a room's ``__init__`` runs at the import of any of its modules.

    RLlib's modules need the ``[rllib]`` extra, which the default install leaves out.
    """
    modules = [n for n in _modules_of("agents") if _room(n) == room and "rllib" not in n]
    loaded = {_room(n) for n in _fresh_import(modules) if n.startswith("agents.")}
    higher = set(AGENT_ROOMS[AGENT_ROOMS.index(room) + 1 :])
    assert modules and not loaded & higher, f"importing agents.{room} loads {sorted(loaded & higher)}"


# --- docs/ARCHITECTURE.md is drawn from the imports ---------------------------------

ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"


def _table(title: str, text: str | None = None) -> list[list[str]]:
    """The body rows of the first table under the page's ``## title``, as lists of cells."""
    text = ARCHITECTURE.read_text(encoding="utf-8") if text is None else text
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    lines = [line for line in text[start : end if end != -1 else None].splitlines() if line.startswith("|")]
    return [[cell.strip() for cell in line.strip().strip("|").split("|")] for line in lines[2:]]


def _names(cell: str) -> list[str]:
    return re.findall(r"`([\w.]+)`", cell)


def _drawn(per_group: str) -> list[set[str]]:
    """One set of names per ``·``-separated part of a cell (``—``: none)."""
    return [set(_names(part)) for part in per_group.split("·")]


def _group_imports() -> dict[str, set[str]]:
    found: dict[str, set[str]] = {}
    for name, imported in import_graph().items():
        group = group_of(name)[1]
        found.setdefault(group, set()).update(group_of(t)[1] for t in imported if group_of(t)[1] != group)
    return found


def _room_imports() -> dict[str, set[str]]:
    found: dict[str, set[str]] = {}
    for name, imported in import_graph().items():
        if name.startswith("agents.") and not name.endswith("__main__"):
            room = _room(name)
            rooms = {_room(t) for t in imported if t.startswith("agents.")}
            found.setdefault(room, set()).update(rooms - {room})
    return found


def architecture_problems(text: str | None = None) -> list[str]:
    """Where the page and the code disagree: the layers, the rooms, the paths of "Where does a new X go"."""
    problems = []
    layers = _table("Layers", text)
    drawn = tuple(tuple(_names(row[1])) for row in layers)
    if [row[0] for row in layers] != [str(i) for i in range(len(LAYERS))] or drawn != LAYERS:
        problems.append(f"the layer table draws {drawn}, LAYERS is {LAYERS}")
    imports = _group_imports()
    for row in layers:
        groups, parts = _names(row[1]), _drawn(row[2])
        if len(parts) != len(groups):
            problems.append(f"layer {row[0]}: {len(groups)} groups, {len(parts)} lists of imports")
        for group, said in zip(groups, parts, strict=False):
            if said != imports.get(group, set()):
                problems.append(f"{group} imports {sorted(imports.get(group, set()))}, the page says {sorted(said)}")
    rooms = _table("Rooms of agents", text)
    if tuple(_names(row[0])[0] for row in rooms) != AGENT_ROOMS:
        problems.append(f"the rooms table lists {[row[0] for row in rooms]}, AGENT_ROOMS is {AGENT_ROOMS}")
    room_imports = _room_imports()
    for row in rooms:
        room = _names(row[0])[0]
        if set(_names(row[1])) != room_imports.get(room, set()):
            problems.append(f"agents.{room} imports {sorted(room_imports.get(room, set()))}, the page says {row[1]}")
    for row in _table("Where does a new X go", text):
        for cell in row[1:]:
            for path in re.findall(r"`([\w./-]+/[\w./-]*)`", cell):
                if not (ROOT / path).exists():
                    problems.append(f"'Where does a new X go' names {path}, which does not exist")
    return problems


def test_the_architecture_page_is_drawn_from_the_imports() -> None:
    assert architecture_problems() == []


def test_the_architecture_check_sees_a_page_that_drifted() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8")
    drifted = {
        "a layer": text.replace("| 3 | `coop_gym.experiment` |", "| 3 | `coop_gym.experiments` |"),
        "an import": text.replace("| 3 | `coop_gym.experiment` | `coop_gym`, ", "| 3 | `coop_gym.experiment` | "),
        "a room": text.replace("| `tune` | `base`, `caregivers`, `evaluate` |", "| `tuning` | `base` |"),
        "a path": text.replace("`estimator/validate.py`", "`estimator/checks.py`"),
    }
    for what, page in drifted.items():
        assert page != text, what
        assert architecture_problems(page), f"a drifted {what} goes unnoticed"
