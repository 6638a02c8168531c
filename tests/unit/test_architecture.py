"""The package's import graph: no cycle, arrows pointing one way, Hydra only in entry points.

The graph is read from the source (every ``import`` statement, including lazy ones inside
functions), so a circle hidden behind a function-level import fails here too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import kinet_rl

SRC = Path(kinet_rl.__file__).resolve().parent
ENTRY_POINTS = {"train", "collect", "evaluate", "tables", "plan"}
#: Layers from the bottom up; a module may import only from its own layer or layers below.
LAYERS = [
    {"keys", "atomic", "devices", "configs", "config_schema", "interrupts", "stats"},
    {"envs"},
    {"data", "planners", "training"},
    {"models"},
    {"baselines"},
    {"evaluation"},
    {"rearrangement"},
    {"comparison"},
    {"pipeline"},
    {"estimate"},
    ENTRY_POINTS,
]


def module_name(path: Path) -> str:
    parts = ["kinet_rl", *path.relative_to(SRC).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in SRC.rglob("*.py")}


def imported_names(path: Path) -> set[str]:
    """Every module an ``import`` in ``path`` names (``from a import b``: ``a.b`` if a module, else ``a``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = (
        module_name(path) if path.name == "__init__.py" else module_name(path).rsplit(".", 1)[0]
    )
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            submodules = {f"{base}.{alias.name}" for alias in node.names}
            names.update(submodules & MODULES.keys())
            if not submodules <= MODULES.keys():
                names.add(base)  # names defined in the package or module itself
    return names


GRAPH = {
    name: {dep for dep in imported_names(path) if dep in MODULES and dep != name}
    for name, path in MODULES.items()
}


def top_level(module: str) -> str:
    """``kinet_rl.models.world_model`` -> ``models``."""
    return module.split(".")[1] if "." in module else ""


def layer_of(module: str) -> int:
    room = top_level(module)
    return next(i for i, layer in enumerate(LAYERS) if room in layer)


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` as a path of module names, or None."""
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                return stack[stack.index(dep) :] + [dep]
            if dep not in state and (cycle := visit(dep)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_cycle_finder_finds_a_lazy_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycle():
    assert find_cycle(GRAPH) is None


def test_every_module_is_in_a_layer():
    rooms = {top_level(m) for m in MODULES} - {""}
    assert rooms <= set().union(*LAYERS), rooms - set().union(*LAYERS)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down(module):
    upward = sorted(
        dep for dep in GRAPH[module] if dep != "kinet_rl" and layer_of(dep) > layer_of(module)
    )
    assert not upward, f"{module} imports from a higher layer: {upward}"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_hydra_only_in_entry_points(module):
    if top_level(module) in ENTRY_POINTS:
        return
    third_party = {name.split(".")[0] for name in imported_names(MODULES[module])}
    assert not third_party & {"hydra", "omegaconf"}, f"{module} imports Hydra"


def test_tables_does_not_import_train():
    assert not any(dep.startswith("kinet_rl.train") for dep in GRAPH["kinet_rl.tables"])


def test_planners_import_neither_models_nor_hydra():
    for module in (m for m in MODULES if top_level(m) == "planners"):
        names = imported_names(MODULES[module])
        assert not any(n.startswith(("kinet_rl.models", "kinet_rl.baselines")) for n in names)
        assert not {n.split(".")[0] for n in names} & {"hydra", "omegaconf"}
