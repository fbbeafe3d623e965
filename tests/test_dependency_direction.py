"""The layers of the project import in one direction only (see ARCHITECTURE.md).

- ``clay_cli`` (the command lines' shared conventions) imports the standard library only;
  ``tiv_model``, ``dem_taichi`` and ``bridge`` may import it;
- ``tiv_model`` imports neither taichi nor ``dem_taichi`` nor ``bridge``;
- ``dem_taichi`` imports nothing of ``tiv_model`` nor ``bridge``;
- ``bridge`` never imports taichi nor the engine (only ``dem_taichi.io`` is allowed);
- inside the repository no module imports a moved module by its old path;
- ``import dem_taichi`` does not initialise Taichi: only ``dem_taichi/engine/runtime.py`` calls
  ``ti.init``;
- inside ``dem_taichi`` the role subpackages are layered (:data:`LAYERS`): a module imports its
  own subpackage and those of lower layers, never one beside or above its own;
- no import loops in any package.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The role subpackages of ``dem_taichi``, bottom layer first (ARCHITECTURE.md). A module may
#: import its own subpackage and the subpackages of lower layers; not a subpackage of its own
#: layer (those stay independent of each other) and not one above.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("physics", "kernels"),  # the numpy reference laws; the Taichi kernels
    ("scene", "io"),  # what a run is asked to do; the files it writes and reads
    ("engine", "analysis"),  # the simulation; numpy analysis of its results
    ("response",),  # linear response of a static network, anisotropy
    ("protocol",),  # the virtual experiments
    ("sweep",),  # many protocol runs on Dask
    ("cli",),  # the command line
)


def imported_modules(package: str) -> dict[str, set[str]]:
    """Map each module file of ``package`` to the absolute module names it imports."""
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        names: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module)
        found[str(path.relative_to(ROOT))] = names
    return found


def offending(package: str, forbidden: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    bad = []
    for path, names in imported_modules(package).items():
        for name in names:
            hit = any(name == f or name.startswith(f + ".") for f in forbidden)
            ok = any(name == a or name.startswith(a + ".") for a in allowed)
            if hit and not ok:
                bad.append(f"{path} imports {name}")
    return bad


#: the project's import packages; anything else ``clay_cli`` imports must be standard library
PROJECT = ("clay_cli", "tiv_model", "dem_taichi", "bridge")


def test_clay_cli_imports_the_standard_library_only():
    imported = {
        name.split(".")[0] for names in imported_modules("clay_cli").values() for name in names
    }
    outside = sorted(
        name
        for name in imported - {"clay_cli", "__future__"}
        if name not in sys.stdlib_module_names
    )
    assert outside == []
    assert offending("clay_cli", PROJECT[1:]) == []


def test_tiv_model_is_standalone():
    assert offending("tiv_model", ("taichi", "dem_taichi", "bridge")) == []


def test_dem_taichi_imports_no_tiv_model_nor_bridge():
    """The engine shares only the command-line conventions (``clay_cli``) with the model."""
    assert offending("dem_taichi", ("tiv_model", "bridge")) == []


#: old module path -> new one (kept for one release, with a DeprecationWarning): no module of
#: the repository imports the old path
OLD_PATHS = {
    "tiv_model.command_line": "clay_cli",
    "bridge.calibration_options": "bridge.calibration.options",
    "bridge.calibration_result": "bridge.calibration.result",
    "bridge.identifiability": "bridge.calibration.identifiability",
}


def test_no_module_imports_an_old_path():
    bad = []
    for package in (*PROJECT, "tests", "scripts", "benchmarks"):
        for path, names in imported_modules(package).items():
            bad += [f"{path} imports {name}" for name in names if name in OLD_PATHS]
    for package in PROJECT:  # relative imports too
        for module, targets in module_imports(package).items():
            bad += [f"{module} imports {t}" for t in targets if t in OLD_PATHS]
    assert bad == []


def test_bridge_reads_results_not_the_engine():
    assert offending("bridge", ("taichi", "dem_taichi"), allowed=("dem_taichi.io",)) == []


def test_only_runtime_initialises_taichi():
    callers = []
    for path in sorted((ROOT / "dem_taichi").rglob("*.py")):
        if "ti.init(" in path.read_text() and path != ROOT / "dem_taichi/engine/runtime.py":
            callers.append(str(path.relative_to(ROOT)))
    assert callers == []


#: every subpackage of dem_taichi but kernels/ loads without Taichi (it is imported when a
#: simulation is built, or inside the function that needs it)
WITHOUT_TAICHI = [f"dem_taichi.{sub}" for names in LAYERS for sub in names if sub != "kernels"]


@pytest.mark.parametrize("package", ["clay_cli", "tiv_model", "bridge", *WITHOUT_TAICHI])
def test_import_does_not_load_taichi(package):
    code = f"import sys, {package}, pkgutil, importlib\n"
    code += "[importlib.import_module(m.name) for m in "
    code += f"pkgutil.walk_packages({package}.__path__, '{package}.')"
    code += " if not m.name.endswith('__main__')]\n"
    code += "assert 'taichi' not in sys.modules, 'taichi was imported'\n"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_import_dem_taichi_does_not_init_taichi():
    code = "import sys, dem_taichi\nassert 'taichi' not in sys.modules\n"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_engine_and_protocol_import_without_taichi():
    """For type use (annotations, isinstance) the engine and the protocol load without Taichi;
    it is imported when a simulation is built."""
    code = "import sys, dem_taichi.engine.simulation, dem_taichi.protocol.runner\n"
    code += "import dem_taichi.protocol.probing\n"
    code += "assert 'taichi' not in sys.modules, 'taichi was imported'\n"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def module_imports(package: str) -> dict[str, set[str]]:
    """Map each module of ``package`` (dotted name) to the modules of ``package`` it imports.

    Every import counts: top level, inside functions and under ``TYPE_CHECKING`` (a lazy import
    hides a loop from Python, not from a reader). ``from a import b`` is an import of ``a.b``
    when that is a module, else of ``a``; relative imports are resolved.
    """
    files = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files[".".join(parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    here = name.split(".") if is_package else name.split(".")[:-1]
                    anchor = here[: len(here) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [
                    f"{base}.{alias.name}" if f"{base}.{alias.name}" in files else base
                    for alias in node.names
                ]
            else:
                continue
            edges.update(t for t in targets if t in files and t != name)
        graph[name] = edges
    return graph


def import_loops(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    loops: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph[node]):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                loops.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(loops)


def test_import_loop_detector_finds_a_loop():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_loops(graph) == [["a", "b", "c"]]
    assert import_loops({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("package", ["clay_cli", "dem_taichi", "tiv_model", "bridge"])
def test_no_import_loops(package):
    """No module of the package imports, even lazily, one that imports it back."""
    assert import_loops(module_imports(package)) == []


#: The modules of ``dem_taichi`` outside the layers, and what of the package each may import:
#: the package's face (version, lazy public names), the old paths' table, the entry point.
OUTSIDE_LAYERS = {
    "dem_taichi": {"dem_taichi._moved"},
    "dem_taichi._moved": set(),
    "dem_taichi.__main__": None,  # None: anything (it only calls the command line)
}


def layer_violations(
    graph: dict[str, set[str]],
    layers: tuple[tuple[str, ...], ...] = LAYERS,
    outside: dict[str, set[str] | None] = OUTSIDE_LAYERS,
    package: str = "dem_taichi",
) -> list[str]:
    """Every import of ``graph`` (module -> modules it imports, :func:`module_imports`) that
    breaks the layering: a module outside the subpackages and :data:`OUTSIDE_LAYERS`, an import
    of a subpackage beside or above the importer's, or an outside module importing what it may
    not. Any module may import the ones of ``outside`` that import nothing of the package."""
    level = {sub: i for i, names in enumerate(layers) for sub in names}
    free = {name for name, allowed in outside.items() if allowed == set()} | {package}
    bad = []

    def subpackage(module: str) -> str | None:
        parts = module.split(".")
        return parts[1] if len(parts) > 1 and parts[1] in level else None

    for module, targets in sorted(graph.items()):
        here = subpackage(module)
        if here is None:
            if module not in outside:
                bad.append(f"{module} is in no layer (put it in a role subpackage)")
                continue
            allowed = outside[module]
            for target in sorted(targets):
                if allowed is not None and target not in allowed:
                    bad.append(f"{module} imports {target} (it may import {sorted(allowed)})")
            continue
        for target in sorted(targets):
            there = subpackage(target)
            if there is None:
                if target not in free:
                    bad.append(f"{module} imports {target}, which is in no layer")
            elif there != here and level[there] >= level[here]:
                where = "beside" if level[there] == level[here] else "above"
                bad.append(f"{module} imports {target}: {there} is {where} {here}")
    return sorted(bad)


def test_layer_check_catches_imports_up_and_sideways():
    graph = {
        "dem_taichi.physics.forcelaw": {"dem_taichi.engine.simulation"},  # up
        "dem_taichi.engine.simulation": {"dem_taichi.physics.forcelaw", "dem_taichi.engine.state"},
        "dem_taichi.engine.state": {"dem_taichi.analysis.findings", "dem_taichi._moved"},  # beside
        "dem_taichi.analysis.findings": {"dem_taichi.io.schema", "dem_taichi"},
        "dem_taichi.io.schema": set(),
        "dem_taichi.helpers": set(),  # a flat module again
        "dem_taichi": {"dem_taichi.engine.simulation"},  # the face imports eagerly
        "dem_taichi._moved": set(),
    }
    assert layer_violations(graph) == [
        "dem_taichi imports dem_taichi.engine.simulation (it may import ['dem_taichi._moved'])",
        "dem_taichi.engine.state imports dem_taichi.analysis.findings: analysis is beside engine",
        "dem_taichi.helpers is in no layer (put it in a role subpackage)",
        "dem_taichi.physics.forcelaw imports dem_taichi.engine.simulation: engine is above physics",
    ]
    ok = {"dem_taichi.cli.commands": {"dem_taichi.sweep.command", "dem_taichi.physics.bonds"}}
    assert layer_violations(ok) == []


def test_every_subpackage_has_a_layer():
    found = {p.parent.name for p in (ROOT / "dem_taichi").glob("*/__init__.py")}
    assert found == {sub for names in LAYERS for sub in names}


def test_dem_taichi_imports_point_down_the_layers():
    """No module of ``dem_taichi`` imports, even lazily or for type checking, a subpackage
    beside or above its own; no module stays outside the subpackages but the listed few."""
    assert layer_violations(module_imports("dem_taichi")) == []


def test_subpackages_form_no_loop():
    graph = module_imports("dem_taichi")
    by_package: dict[str, set[str]] = {}
    for module, targets in graph.items():
        here = ".".join(module.split(".")[:2])
        by_package.setdefault(here, set()).update(".".join(t.split(".")[:2]) for t in targets)
    for here, targets in by_package.items():
        targets.discard(here)
        targets &= set(by_package)
    assert import_loops(by_package) == []
