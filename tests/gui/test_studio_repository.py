"""Issue 45: the add-on installed and updated from a studio's extension repository (docs/studio.md).

A studio admin's steps run between Blender sessions as they would on the command line: build the
repository with scripts/build_repo.py, ``blender --command extension repo-add / sync / install /
update`` in a user folder of its own. The artist's steps run in two Blender windows of their own
(this test's Blender only conducts): drag a handle of a rig made in version A and save; after
version B is published into the same folder and updated, reopen the file and drag again."""

import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import tomllib

import bpy
import numpy as np

import gui
import rigs

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
#: The rig the artist saves in the first session and reopens in the second.
RIG = "rig.blend"


def _manifest_version(package):
    return tomllib.loads((pathlib.Path(package.__file__).parent / "blender_manifest.toml").read_text())["version"]


def _studio_addon(expected_version):
    package = gui.addon()
    assert package.__name__ == "bl_ext.studio.skin_detach_addon", f"the add-on enabled is {package.__name__}"
    version = _manifest_version(package)
    assert version == expected_version, f"the installed add-on is version {version}, expected {expected_version}"


def first_session(ui):
    """The artist, in version A: a small rig, a drag of its handle, Ctrl+S."""
    yield from ui.setup()
    _studio_addon(os.environ["STUDIO_VERSION"])
    obj, handle = rigs.rig(ui)
    with bpy.context.temp_override(window=ui.window):
        bpy.ops.wm.save_as_mainfile(filepath=os.environ["STUDIO_RIG"])  # set-up: the file has a name
    rest = rigs.positions(obj).copy()
    yield from rigs.drag(ui, 60, 20)
    assert np.abs(rigs.positions(obj) - rest).max() > 0.05, "the drag did not move the mesh"
    yield from ui.hover_view()
    yield from ui.press('S', ctrl=True, wait=1.5)


def second_session(ui):
    """The artist, after the update: the saved file (opened at start) drags again."""
    yield from ui.setup()
    _studio_addon(os.environ["STUDIO_VERSION"])
    obj = bpy.data.objects["Sphere"]
    assert rigs.api().bound_objects([obj]), "the reopened mesh is not bound"
    active = bpy.context.view_layer.objects.active
    assert active is not None and "_skin_detach_handle" in active, f"the file opened with {active} active, not the handle"
    before = rigs.positions(obj).copy()
    assert np.abs(before - rigs.api().rest_positions(obj)).max() > 0.05, "the saved pose was lost"
    yield from rigs.drag(ui, -80, 0)
    after = rigs.positions(obj)
    assert np.isfinite(after).all() and np.abs(after - before).max() > 0.05, "the second drag did not move the mesh"


class Studio:
    """The admin's side: a repository folder, a Blender user folder, the command lines."""

    def __init__(self):
        self.folder = pathlib.Path(tempfile.mkdtemp(prefix="studio-"))
        self.repo = self.folder / "repo"
        self.env = dict(os.environ, BLENDER_USER_RESOURCES=str(self.folder / "user"), STUDIO_RIG=str(self.folder / RIG))
        scripts = pathlib.Path(bpy.utils.system_resource('SCRIPTS'))
        self.tool = scripts / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
        self.out = pathlib.Path(sys.argv[sys.argv.index("--result") + 1]).parent
        self.python = sys.executable if pathlib.Path(sys.executable).name.startswith("python") else \
            shutil.which("python3")

    def run(self, command, timeout=120, **extra):
        done = subprocess.run(command, env=dict(self.env, **extra), capture_output=True, text=True, timeout=timeout)
        assert done.returncode == 0, f"{' '.join(map(str, command))}: exit {done.returncode}: " \
                                     f"{(done.stdout + done.stderr).strip()[-1500:]}"
        return done.stdout

    def extension(self, *arguments):
        return self.run([bpy.app.binary_path, "--online-mode", "--command", "extension", *arguments])

    def publish(self, source):
        """scripts/build_repo.py of ``source`` (a copy of the project) into the repository folder."""
        return self.run([self.python, str(source / "scripts" / "build_repo.py"), "--platforms", "linux-x64",
                         "--out", str(self.repo), "--wheels", str(ROOT / "build" / "wheels")],
                        BLENDER_EXT=str(self.tool))

    def session(self, name, version, blend=None):
        """A Blender window of the artist running ``name`` of this module by events; its result."""
        result = self.out / f"{__name__}.{name}.json"  # next to this test's result: a failure's screenshot too
        command = [bpy.app.binary_path, "--enable-event-simulate", *([str(blend)] if blend else []), "--python",
                   str(ROOT / "tests" / "gui" / "runner.py"), "--", "--test", f"{__name__}::{name}",
                   "--result", str(result)]
        done = subprocess.run(command, env=dict(self.env, STUDIO_VERSION=version), capture_output=True, text=True,
                              timeout=150)
        result.with_suffix(".log").write_text(done.stdout + done.stderr)
        assert result.exists(), f"{name}: no result (exit {done.returncode}): {(done.stdout + done.stderr)[-1500:]}"
        outcome = json.loads(result.read_text())
        assert outcome["passed"], f"{name}: {outcome['message']}"


def test_install_and_update_from_a_studio_repository(ui):
    studio = Studio()
    yield 0.5
    version = tomllib.loads((ROOT / "blender_manifest.toml").read_text())["version"]
    written = studio.publish(ROOT)
    assert "index.json" in written, written
    studio.extension("repo-add", "--name", "studio", "--url", (studio.repo / "index.json").as_uri(), "studio")
    studio.extension("sync")
    studio.extension("install", "-s", "-e", "studio.skin_detach_addon")
    yield 0.1
    studio.session("first_session", version)
    assert (studio.folder / RIG).exists(), "the artist's file was not saved"
    yield 0.1

    # Version B: a copy of the project with the manifest's version one patch higher, published.
    source = studio.folder / "source"
    for name in ("scripts", "skin_detach_addon"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    major, minor, patch = map(int, version.split("."))
    newer = f"{major}.{minor}.{patch + 1}"
    manifest = (ROOT / "blender_manifest.toml").read_text()
    (source / "blender_manifest.toml").write_text(manifest.replace(f'version = "{version}"', f'version = "{newer}"', 1))
    studio.publish(source)
    assert (studio.repo / "archive" / f"skin_detach_addon-{version}-linux_x64.zip").exists()
    studio.extension("sync")
    updated = studio.extension("update")
    installed = studio.folder / "user" / "extensions" / "studio" / "skin_detach_addon" / "blender_manifest.toml"
    assert f'version = "{newer}"' in installed.read_text(), f"the update did not install {newer}: {updated[-800:]}"
    yield 0.1
    studio.session("second_session", newer, blend=studio.folder / RIG)
    shutil.rmtree(studio.folder)
