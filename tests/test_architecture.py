"""The package's structure, checked: small modules, short functions, no import cycle inside a
package, and the configuration's registry look-ups (which import-linter cannot see).

ARCHITECTURE.md says where each concept lives; import-linter (`make lint`) checks the
layers between packages (the contracts at the end of pyproject.toml). These tests check
what the contracts do not: a module stays under `MAX_MODULE_LINES` lines, a function under
`MAX_FUNCTION_LINES` (numba's compiled kernels aside: a kernel is one loop nest, and calls
cost inside it), the modules of one package import each other one way only, and each
registry the configuration names by string resolves, in a stage it may name.
"""

from __future__ import annotations

import ast
import dataclasses
import tomllib
from collections.abc import Iterator, Mapping
from functools import cache
from pathlib import Path

import grimp
import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "rafostrack"
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 60
NUMBA_COMPILERS = {"njit", "jit", "vectorize", "guvectorize"}  # numba's decorators of compiled kernels
CONFIG_MODULES = ("rafostrack/config.py", "rafostrack/config_sections.py")
# The stages whose registries `[section]` keys may name (`config_sections.RegistryChoices`),
# as the pipeline contract orders them: from the filter down to the measurement model.
REGISTRY_LAYERS = ("rafostrack.filtering", "rafostrack.model")

MODULES = sorted(PACKAGE.rglob("*.py"))


def _name(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


# --------------------------------------------------------------------------------------
# Sizes


@pytest.mark.parametrize("path", MODULES, ids=_name)
def test_module_is_small(path: Path) -> None:
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_MODULE_LINES, f"{_name(path)}: {lines} lines (at most {MAX_MODULE_LINES}); split it by concept"


def _numba_names(tree: ast.Module) -> tuple[set[str], set[str]]:
    """The names a module binds to numba's compilers (`from numba import njit`) and to numba
    itself (`import numba as nb`)."""
    compilers, modules = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "numba":
            compilers |= {a.asname or a.name for a in node.names if a.name in NUMBA_COMPILERS}
        elif isinstance(node, ast.Import):
            modules |= {a.asname or a.name for a in node.names if a.name == "numba"}
    return compilers, modules


def _compiled(function: ast.FunctionDef | ast.AsyncFunctionDef, compilers: set[str], modules: set[str]) -> bool:
    """Whether a numba compiler decorates `function` (`@njit`, `@njit(...)`, `@numba.jit(...)`)."""
    for decorator in function.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        if isinstance(target, ast.Name) and target.id in compilers:
            return True
        if (
            isinstance(target, ast.Attribute)
            and target.attr in NUMBA_COMPILERS
            and isinstance(target.value, ast.Name)
            and target.value.id in modules
        ):
            return True
    return False


def long_functions(source: str) -> list[tuple[str, int]]:
    """(name, lines) of the functions and methods in `source` over `MAX_FUNCTION_LINES`, from
    the `def` line to the last, numba's compiled kernels left out."""
    tree = ast.parse(source)
    compilers, modules = _numba_names(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not _compiled(node, compilers, modules):
            lines = (node.end_lineno or node.lineno) - node.lineno + 1
            if lines > MAX_FUNCTION_LINES:
                found.append((node.name, lines))
    return found


@pytest.mark.parametrize("path", MODULES, ids=_name)
def test_functions_are_short(path: Path) -> None:
    found = long_functions(path.read_text(encoding="utf-8"))
    assert not found, f"{_name(path)}: functions over {MAX_FUNCTION_LINES} lines: " + ", ".join(
        f"{name} ({lines})" for name, lines in found
    )


def test_long_function_check_spares_only_compiled_kernels() -> None:
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    source = (
        "import numba\nfrom numba import njit as fast\n\n"
        f"def plain():\n{body}\n"
        f"@fast(cache=True)\ndef kernel():\n{body}\n"
        f"@numba.jit\ndef other_kernel():\n{body}\n"
        f"@functools.cache\ndef cached():\n{body}\n"
    )
    assert long_functions(source) == [("plain", MAX_FUNCTION_LINES + 1), ("cached", MAX_FUNCTION_LINES + 1)]


# --------------------------------------------------------------------------------------
# Import cycles inside a package


@cache
def _graph() -> grimp.ImportGraph:
    """The package's import graph (every import, also those under TYPE_CHECKING or in a
    function), built afresh: no cache written in the repository."""
    return grimp.build_graph("rafostrack", cache_dir=None)


def _subpackages() -> list[str]:
    graph = _graph()
    return sorted(m for m in graph.find_children("rafostrack") if graph.find_children(m))


def cycles(modules: list[str], imports: Mapping[str, set[str]]) -> list[list[str]]:
    """The import cycles among `modules`: each strongly connected set of more than one module
    (or a module importing itself), sorted (Tarjan's algorithm, without recursion)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in modules:
        if root in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(root, iter(sorted(imports.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            module, targets = work[-1]
            target = next(targets, None)
            if target is not None:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(imports.get(target, ())))))
                elif target in on_stack:
                    low[module] = min(low[module], index[target])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[module])
            if low[module] == index[module]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == module:
                        break
                if len(component) > 1 or module in imports.get(module, ()):
                    found.append(sorted(component))
    return sorted(found)


def test_cycles_finds_a_cycle() -> None:
    imports = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    assert cycles(["a", "b", "c", "d", "e"], imports) == [["a", "b", "c"], ["e"]]
    assert cycles(["a", "b"], {"a": {"b"}}) == []


@pytest.mark.parametrize("package", _subpackages())
def test_no_import_cycle_inside_package(package: str) -> None:
    graph = _graph()
    modules = sorted({package, *graph.find_descendants(package)})
    inside = set(modules)
    imports = {m: graph.find_modules_directly_imported_by(m) & inside for m in modules}
    found = cycles(modules, imports)
    assert not found, f"{package}: modules importing each other (move the shared piece to its own module): " + (
        "; ".join(" <-> ".join(c) for c in found)
    )


# --------------------------------------------------------------------------------------
# The configuration's registries


def _contract(contract_id: str) -> dict:
    config = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    return next(c for c in config["tool"]["importlinter"]["contracts"] if c["id"] == contract_id)


def _layer_of(module: str, layers: list[str]) -> int | None:
    """The position of `module`'s layer in the pipeline contract (None: in none of them)."""
    for position, layer in enumerate(layers):
        if any(module == m or module.startswith(m + ".") for m in (part.strip() for part in layer.split("|"))):
            return position
    return None


def _registry_lookups() -> list[tuple[str, str, object]]:
    """(section, key, RegistryChoices) of each key whose choices are a registry's names."""
    from rafostrack.config import SECTIONS
    from rafostrack.config_sections import RegistryChoices

    return [
        (section, f.name, f.metadata["choices"])
        for section, cls in SECTIONS.items()
        for f in dataclasses.fields(cls)
        if isinstance(f.metadata.get("choices"), RegistryChoices)
    ]


def test_config_names_registries_only_through_registry_choices() -> None:
    """Every string look-up of the configuration is a `RegistryChoices` of a section's field
    (so that the test below sees them all): no other `import_module` or `__import__`."""
    calls = 0
    for relative in CONFIG_MODULES:
        tree = ast.parse((REPO / relative).read_text(encoding="utf-8"))
        allowed: set[int] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name == "RegistryChoices":
                allowed |= {id(inner) for inner in ast.walk(node)}
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "RegistryChoices":
                calls += 1
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
                if name in ("import_module", "__import__"):
                    assert id(node) in allowed, (
                        f"{relative}:{node.lineno}: a module imported by name outside RegistryChoices"
                    )
    assert calls == len(_registry_lookups()) >= 4


@pytest.mark.parametrize("section, key, lookup", _registry_lookups(), ids=lambda v: str(getattr(v, "name", v)))
def test_config_registry_resolves_in_an_allowed_stage(section: str, key: str, lookup) -> None:
    """The registry exists, holds names (the default among them), and lives in a core stage
    above the configuration that config's fields may name (`REGISTRY_LAYERS`): import-linter
    cannot see a module imported by name, so a registry moved to another stage, into a side
    package or away fails here."""
    import importlib

    from rafostrack.config import default_layer

    layers = _contract("pipeline")["layers"]
    first, last = (_layer_of(m, layers) for m in REGISTRY_LAYERS)
    assert first is not None and last is not None
    where = _layer_of(lookup.module, layers)
    assert where is not None and first <= where <= last, (
        f"[{section}] {key}: its registry {lookup.module}.{lookup.name} is in no stage from {REGISTRY_LAYERS[0]} "
        f"to {REGISTRY_LAYERS[1]} (the pipeline contract's layers)"
    )
    assert not any(
        lookup.module == m or lookup.module.startswith(m + ".") for m in _contract("side-packages")["forbidden_modules"]
    )
    module = importlib.import_module(lookup.module)
    assert hasattr(module, lookup.name), f"[{section}] {key}: {lookup.module} has no registry {lookup.name}"
    registry = getattr(module, lookup.name)
    assert isinstance(registry, Mapping | list | tuple) and registry, f"{lookup.module}.{lookup.name}: not a registry"
    names = list(lookup())
    assert names and all(isinstance(n, str) for n in names)
    assert default_layer()[section][key] in names
