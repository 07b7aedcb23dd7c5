"""scripts/build_extension.py: the linux-x64 zip builds, validates, installs into an isolated
Blender user folder and runs Build + Apply through the installed copy (downloads wheels)."""

import os
import pathlib
import subprocess
import sys
import zipfile

import pytest

pytest.importorskip("bpy")

ROOT = pathlib.Path(__file__).resolve().parent.parent

INSTALL_AND_RUN = r'''
import glob, os, sys
import numpy as np
import bpy

bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
assert "bl_ext.user_default.skin_detach_addon" in sys.modules, "extension not enabled"
assert "skin_detach_addon" not in sys.modules, "the repository copy was imported"
site = os.path.join(bpy.utils.user_resource("EXTENSIONS"), ".local", "lib",
                    "python%d.%d" % sys.version_info[:2], "site-packages")
for package in ("scipy", "fast_simplification"):
    assert os.path.isdir(os.path.join(site, package)), f"{package} wheel not installed in {site}"

bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
obj = bpy.context.active_object
bpy.context.scene.skin_detach.target_faces = 200
assert bpy.ops.skin_detach.build() == {"FINISHED"}
z = np.array([v.co.z for v in obj.data.vertices])
rest = np.array([v.co[:] for v in obj.data.vertices])
for mask, op in ((z < -0.8, bpy.ops.skin_detach.add_anchor), (z > 0.8, bpy.ops.skin_detach.add_handle)):
    bpy.context.view_layer.objects.active = obj
    obj.data.vertices.foreach_set("select", mask)
    assert op() == {"FINISHED"}
handle = bpy.context.active_object
handle.location.x += 0.5
assert bpy.ops.skin_detach.apply() == {"FINISHED"}
moved = np.array([v.co[:] for v in obj.data.vertices])
assert abs((moved - rest)[z > 0.9, 0].mean() - 0.5) < 0.05, (moved - rest)[z > 0.9, 0].mean()
assert np.abs(moved - rest)[z < -0.9].max() < 1e-3
print("installed extension works")
'''


def test_linux_zip_builds_validates_installs_and_runs(tmp_path):
    build = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platforms", "linux-x64",
                            "--out", str(tmp_path / "dist"), "--wheels", str(tmp_path / "wheels")],
                           capture_output=True, text=True, timeout=1200)
    assert build.returncode == 0, build.stderr
    zips = list((tmp_path / "dist").glob("*.zip"))
    assert [z.name for z in zips] == ["skin_detach_addon-0.1.0-linux_x64.zip"]
    with zipfile.ZipFile(zips[0]) as archive:
        names = archive.namelist()
        manifest = archive.read("blender_manifest.toml").decode()
    assert sum(n.startswith("wheels/scipy-1.17.1-cp311") for n in names) == 1
    assert sum(n.startswith("wheels/scipy-1.17.1-cp313") for n in names) == 1
    assert 'platforms = ["linux-x64"]' in manifest and 'license = ["SPDX:GPL-3.0-or-later"]' in manifest
    assert not any("__pycache__" in n or n.startswith("tests/") for n in names)

    script = tmp_path / "install_and_run.py"
    script.write_text(INSTALL_AND_RUN)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    run = subprocess.run([sys.executable, str(script), str(zips[0])], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and "installed extension works" in run.stdout, run.stdout[-2000:] + run.stderr[-2000:]


def test_build_refuses_unknown_platforms(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platforms", "amiga",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "--platforms" in run.stderr
