"""The add-on's layers import one way: ui -> api -> blender -> core, and ship no bench code."""

import ast
import pathlib
import subprocess
import sys

import pytest

ADDON = pathlib.Path(__file__).resolve().parent.parent / "skin_detach_addon"


def imported_packages(path):
    """Add-on subpackages (``api``, ``blender``, ``core``, ``ui``) one module imports, relative or absolute."""
    layer = path.relative_to(ADDON).parts[0] if len(path.relative_to(ADDON).parts) > 1 else None
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level == 0:
                parts = module.split(".")
                if parts[0] == "skin_detach_addon":
                    found.add(parts[1] if len(parts) > 1 else "")
                elif parts[0] in ("bench", "scripts", "tests"):
                    found.add(parts[0])
                continue
            if node.level == 1 and layer is not None:
                found.add(layer)
                continue
            top = module.split(".")[0] if module else None
            names = [top] if top else [alias.name for alias in node.names]
            found.update(names)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in ("bench", "scripts", "tests"):
                    found.add(alias.name.split(".")[0])
    return found


ALLOWED = {
    "ui": {"ui", "api"},
    "blender": {"blender", "core"},
    "core": {"core"},
}


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_each_layer_imports_only_what_is_below_it(layer):
    for path in sorted((ADDON / layer).glob("*.py")):
        bad = imported_packages(path) - ALLOWED[layer]
        assert not bad, f"{path.relative_to(ADDON)} imports {sorted(bad)}"


def test_api_imports_blender_and_core_only():
    assert imported_packages(ADDON / "api.py") <= {"blender", "core"}


def test_the_bake_cli_imports_the_api_only():
    assert imported_packages(ADDON / "bake_cli.py") <= {"api"}


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
