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
ENTRY_POINTS = {"train", "collect", "evaluate", "tables", "plan", "import_data"}
#: Layers from the bottom up; a module may import only from its own layer or layers below.
LAYERS = [
    {"keys", "atomic", "devices", "configs", "config_schema", "interrupts", "stats"},
    {"envs"},
    {"data", "planners", "training"},
    {"models"},
    {"baselines"},
    {"evaluation", "rows"},
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


def model_classes() -> set[str]:
    """Names of the model classes: every class of ``models``/``baselines`` that declares what it
    can do (``capabilities``), and their bases that are models too."""
    import inspect

    import kinet_rl.baselines
    import kinet_rl.models

    names = set()
    for package in (kinet_rl.models, kinet_rl.baselines):
        for _, cls in inspect.getmembers(package, inspect.isclass):
            if hasattr(cls, "capabilities"):
                names.update(
                    base.__name__
                    for base in cls.__mro__
                    if base.__module__.startswith(("kinet_rl.models", "kinet_rl.baselines"))
                )
    return names - {"ConfigCheckpointMixin"}


def class_dispatch(source: str, classes: set[str]) -> list[str]:
    """Each ``isinstance``/``issubclass`` test against one of ``classes`` in ``source``, and each
    ``getattr`` of a model's declaration by string (``getattr(model, "...")``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name):
            continue
        if node.func.id in ("isinstance", "issubclass") and len(node.args) == 2:
            tested = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
            tested |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
            found += [
                f"line {node.lineno}: {node.func.id}(..., {name})" for name in tested & classes
            ]
        model = node.args[0] if node.args else None
        named = isinstance(model, ast.Name) and model.id in ("model", "net", "model_class")
        if node.func.id == "getattr" and named and len(node.args) > 1:
            found.append(f"line {node.lineno}: getattr({node.args[0].id}, ...)")
    return found


def test_class_dispatch_finder_finds_dispatch():
    classes = {"KINetWorldModel", "VCDNWorldModel"}
    source = (
        "a = isinstance(net, KINetWorldModel)\n"
        "b = issubclass(cls, (models.VCDNWorldModel, int))\n"
        "c = getattr(model, 'variable_object_count', False)\n"
        "d = isinstance(x, dict)\n"
    )
    assert len(class_dispatch(source, classes)) == 3


def test_no_dispatch_on_model_classes_outside_the_row_registry():
    """Behaviour comes from what a model declares (``capabilities``, ``planning``,
    ``model_file``) or from the row registry (``kinet_rl.rows``), never from its class."""
    classes = model_classes()
    assert {"KINetWorldModel", "VCDNWorldModel", "ObjectInteractionModel"} <= classes
    offenders = {
        module: found
        for module, path in MODULES.items()
        if module != "kinet_rl.rows" and (found := class_dispatch(path.read_text(), classes))
    }
    assert not offenders, offenders
