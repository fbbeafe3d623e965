"""The layers of the project import in one direction only (see ARCHITECTURE.md).

- ``tiv_model`` imports neither taichi nor ``dem_taichi`` nor ``bridge``;
- ``bridge`` never imports taichi nor the engine (only ``dem_taichi.io`` is allowed);
- ``import dem_taichi`` does not initialise Taichi: only ``dem_taichi/runtime.py`` calls
  ``ti.init``.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


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


def test_tiv_model_is_standalone():
    assert offending("tiv_model", ("taichi", "dem_taichi", "bridge")) == []


def test_bridge_reads_results_not_the_engine():
    assert offending("bridge", ("taichi", "dem_taichi"), allowed=("dem_taichi.io",)) == []


def test_only_runtime_initialises_taichi():
    callers = []
    for path in sorted((ROOT / "dem_taichi").rglob("*.py")):
        if "ti.init(" in path.read_text() and path.name != "runtime.py":
            callers.append(str(path.relative_to(ROOT)))
    assert callers == []


@pytest.mark.parametrize("package", ["tiv_model", "bridge"])
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
