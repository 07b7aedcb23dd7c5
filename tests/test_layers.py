"""The add-on's layers import one way: ui -> api -> blender -> core, and ship no bench code;
inside core, the skin-detached surface and the proxy solve import only themselves and the shared
modules, never each other (only core's own __init__ imports both)."""

import ast
import pathlib
import subprocess
import sys

import pytest

ADDON = pathlib.Path(__file__).resolve().parent.parent / "skin_detach_addon"
CORE = ADDON / "core"
#: The core modules both halves build on, at core/'s top level.
SHARED = {"errors", "validation", "threads", "blas_threads", "geometry", "packed_arrays"}
#: The paper's two halves, a subpackage of core each.
HALVES = ("detached_surface", "proxy_solve")
#: What each part of core may import: itself and the shared modules.
CORE_ALLOWED = {"shared": {"shared"}, "detached_surface": {"detached_surface", "shared"},
                "proxy_solve": {"proxy_solve", "shared"}}
#: Packages outside the standard library that core may import.
CORE_THIRD_PARTY = {"numpy", "scipy", "fast_simplification"}


def imported_modules(path, source=None):
    """Absolute dotted names one module of the add-on (or ``source`` read as that module) imports,
    relative imports resolved: ``from X import a`` gives ``X.a`` (``a`` a submodule or a name)."""
    package = path.relative_to(ADDON.parent).with_suffix("").parts[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text() if source is None else source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = list(package[:len(package) - node.level + 1]) if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            found.update(f"{module}.{alias.name}" for alias in node.names)
    return found


def imported_packages(path):
    """Add-on subpackages (``api``, ``blender``, ``core``, ``ui``) one module imports, relative or
    absolute, and the repository's unshipped packages (``bench``, ``scripts``, ``tests``)."""
    found = set()
    for name in imported_modules(path):
        parts = name.split(".")
        if parts[0] == "skin_detach_addon" and len(parts) > 1:
            found.add(parts[1])
        elif parts[0] in ("bench", "scripts", "tests"):
            found.add(parts[0])
    return found


def core_part(name):
    """The part of core the dotted ``name`` lies in: ``shared``, one of :data:`HALVES`, ``core``
    (a name of the package itself, whose __init__ imports both halves), or None outside core."""
    parts = name.split(".")
    if parts[:2] != ["skin_detach_addon", "core"]:
        return None
    if len(parts) > 2 and parts[2] in SHARED:
        return "shared"
    if len(parts) > 2 and parts[2] in HALVES:
        return parts[2]
    return "core"


def core_parts_imported(path, source=None):
    """Parts of core (:func:`core_part`) the module ``path`` (or ``source`` read as it) imports."""
    return {core_part(name) for name in imported_modules(path, source)} - {None}


def core_modules():
    """(path, part) of every module of core but core/__init__.py."""
    for path in sorted(CORE.rglob("*.py")):
        if path != CORE / "__init__.py":
            yield path, core_part(".".join(path.relative_to(ADDON.parent).with_suffix("").parts))


ALLOWED = {
    "ui": {"ui", "api"},
    "blender": {"blender", "core"},
    "core": {"core"},
}


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_each_layer_imports_only_what_is_below_it(layer):
    for path in sorted((ADDON / layer).rglob("*.py")):
        bad = imported_packages(path) - ALLOWED[layer]
        assert not bad, f"{path.relative_to(ADDON)} imports {sorted(bad)}"


def test_api_imports_blender_and_core_only():
    assert imported_packages(ADDON / "api.py") <= {"blender", "core"}


def test_the_bake_cli_imports_the_api_only():
    assert imported_packages(ADDON / "bake_cli.py") <= {"api"}


def test_core_is_its_two_halves_over_the_shared_modules():
    folders = {p.name for p in CORE.iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert folders == set(HALVES)
    assert {p.stem for p in CORE.glob("*.py")} == SHARED | {"__init__"}
    assert all((CORE / half / "__init__.py").is_file() for half in HALVES)


def test_core_imports_numpy_scipy_and_the_standard_library_only():
    for path in sorted(CORE.rglob("*.py")):
        outside = {name.split(".")[0] for name in imported_modules(path)} - {"skin_detach_addon"}
        bad = outside - CORE_THIRD_PARTY - set(sys.stdlib_module_names)
        assert not bad, f"{path.relative_to(ADDON)} imports {sorted(bad)}"


@pytest.mark.parametrize("part", sorted(CORE_ALLOWED))
def test_each_part_of_core_imports_only_itself_and_the_shared_modules(part):
    checked = [path for path, of in core_modules() if of == part]
    assert checked
    for path in checked:
        bad = core_parts_imported(path) - CORE_ALLOWED[part]
        assert not bad, f"{path.relative_to(ADDON)} ({part}) imports {sorted(bad)}"


def test_only_the_core_package_imports_both_halves():
    both = [path.relative_to(ADDON).as_posix() for path in sorted(CORE.rglob("*.py"))
            if set(HALVES) <= core_parts_imported(path)]
    assert both == ["core/__init__.py"]


@pytest.mark.parametrize("module, line, bad", [
    ("proxy_solve/rotations.py", "from ..detached_surface.skin import Skin", {"detached_surface"}),
    ("proxy_solve/rotations.py", "from ...core.detached_surface import SkinDetachedSurface", {"detached_surface"}),
    ("proxy_solve/rotations.py", "import skin_detach_addon.core.detached_surface.skin", {"detached_surface"}),
    ("detached_surface/skin.py", "from skin_detach_addon.core.proxy_solve import rotations", {"proxy_solve"}),
    ("detached_surface/skin.py", "from .. import SkinDetachError", {"core"}),
    ("geometry.py", "from .proxy_solve.dual_laplacian import DualLaplacian", {"proxy_solve"}),
    ("proxy_solve/rotations.py", "from .. import threads\nfrom ..geometry import unit_rows\nfrom . import x", set()),
])
def test_the_check_sees_an_import_across_the_halves(module, line, bad):
    part = core_part(".".join(("skin_detach_addon", "core", *pathlib.PurePath(module).with_suffix("").parts)))
    assert core_parts_imported(CORE / module, line) - CORE_ALLOWED[part] == bad


def test_importing_the_api_loads_no_ui():
    pytest.importorskip("bpy")
    code = ("import sys, bpy\n"
            "from skin_detach_addon import api\n"
            "assert not any(m.startswith('skin_detach_addon.ui') for m in sys.modules), sorted(sys.modules)\n"
            "assert not hasattr(bpy.types, 'SKIN_DETACH_OT_build') and not hasattr(bpy.types.Scene, 'skin_detach')\n"
            "print('ok')")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=ADDON.parent)
    assert run.returncode == 0 and "ok" in run.stdout, run.stderr[-2000:]
