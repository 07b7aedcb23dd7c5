"""scripts/build_extension.py: the linux-x64 zip builds, validates, installs into an isolated
Blender user folder and runs Build + Apply through the installed copy (downloads wheels)."""

import os
import pathlib
import subprocess
import sys
import zipfile

import pytest

pytest.importorskip("bpy")

from skin_detach_addon.bake_cli import FARM_EXPR  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent

#: Ends a script that runs the bpy module as Blender would exit.
LEAVE = r'''
def leave(code=0):
    """Exit with ``code``. The bpy 4.2 module crashes at interpreter exit once a property with an
    update callback is registered (any add-on's; a real Blender exits through its window manager):
    there the process ends at once, after flushing."""
    if isinstance(code, str):
        print(code, file=sys.stderr)
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    if bpy.app.version[:2] == (4, 2):
        os._exit(code or 0)
    sys.exit(code)
'''

INSTALL_AND_RUN = r'''
import glob, os, sys
import numpy as np
import bpy

''' + LEAVE + r'''
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
leave()
'''


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory):
    """(path of the built linux-x64 zip, the build's folder)."""
    folder = tmp_path_factory.mktemp("extension")
    build = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platforms", "linux-x64",
                            "--out", str(folder / "dist"), "--wheels", str(folder / "wheels")],
                           capture_output=True, text=True, timeout=1200)
    assert build.returncode == 0, build.stderr
    return list((folder / "dist").glob("*.zip")), folder


def test_linux_zip_builds_validates_installs_and_runs(extension_zip, tmp_path):
    zips, _ = extension_zip
    assert [z.name for z in zips] == ["skin_detach_addon-0.1.0-linux_x64.zip"]
    with zipfile.ZipFile(zips[0]) as archive:
        names = archive.namelist()
        manifest = archive.read("blender_manifest.toml").decode()
    assert sum(n.startswith("wheels/scipy-1.17.1-cp311") for n in names) == 1
    assert sum(n.startswith("wheels/scipy-1.17.1-cp313") for n in names) == 1
    assert sum(n.startswith("wheels/fast_simplification-0.2.0-cp314") for n in names) == 1  # distributions' Blender
    assert 'platforms = ["linux-x64"]' in manifest and 'license = ["SPDX:GPL-3.0-or-later"]' in manifest
    assert not any("__pycache__" in n or n.startswith("tests/") for n in names)

    script = tmp_path / "install_and_run.py"
    script.write_text(INSTALL_AND_RUN)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    run = subprocess.run([sys.executable, str(script), str(zips[0])], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and "installed extension works" in run.stdout, run.stdout[-2000:] + run.stderr[-2000:]


def test_every_platform_builds_and_validates_with_its_own_pythons_wheels(tmp_path):
    """What `make extension` builds: one zip per platform, each validated by Blender's tool (the
    script checks); CPython 3.11 and 3.13 wheels everywhere, 3.14 in the Linux zips only."""
    build = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--out", str(tmp_path / "dist"),
                            "--wheels", str(tmp_path / "wheels")], capture_output=True, text=True, timeout=1800)
    assert build.returncode == 0, build.stderr[-2000:]
    zips = sorted((tmp_path / "dist").glob("*.zip"))
    assert [z.name.rsplit("-", 1)[1] for z in zips] == [
        "linux_arm64.zip", "linux_x64.zip", "macos_arm64.zip", "macos_x64.zip", "windows_x64.zip"]
    for path in zips:
        with zipfile.ZipFile(path) as archive:
            wheels = [n for n in archive.namelist() if n.startswith("wheels/")]
        for package in ("scipy-1.17.1", "fast_simplification-0.2.0"):
            tags = sorted(n.split("-")[2] for n in wheels if n.startswith(f"wheels/{package}-"))
            expected = ["cp311", "cp313", "cp314"] if "linux" in path.name else ["cp311", "cp313"]
            assert tags == expected, (path.name, package, tags)


def test_build_refuses_unknown_platforms(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platforms", "amiga",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "--platforms" in run.stderr


#: A stand-in for Blender's command line on a farm worker, ``blender -b [-y] FILE
#: [--python-exit-code N] --python-expr EXPR -- ARGS``, with the bpy module and Blender's rules:
#: it starts with the user's preferences (so the extensions enabled there load, from whatever
#: repository), opens FILE, runs EXPR, and after an uncaught Python error exits N, or 0 when no
#: --python-exit-code was given (sys.exit keeps its code); the repository is not on the path.
BLENDER_STAND_IN = r'''
import os, sys, traceback
import bpy

''' + LEAVE + r'''
argv = sys.argv[1:sys.argv.index("--")] if "--" in sys.argv else sys.argv[1:]
exit_code, blend, expr = 0, None, None
while argv:
    arg = argv.pop(0)
    if arg == "--python-exit-code":
        exit_code = int(argv.pop(0))
    elif arg == "--python-expr":
        expr = argv.pop(0)
    elif arg not in ("-b", "--background", "-y"):
        blend = arg
if os.path.isfile(os.path.join(bpy.utils.user_resource("CONFIG"), "userpref.blend")):
    bpy.ops.wm.read_userpref()
bpy.ops.wm.open_mainfile(filepath=blend)
try:
    exec(compile(expr, "<string>", "exec"), {"__name__": "__main__"})
except SystemExit as stop:
    leave(stop.code)
except BaseException:
    traceback.print_exc()
    leave(exit_code)
assert "skin_detach_addon" not in sys.modules, "the repository copy was imported"
leave()
'''

MAKE_RIG = r'''
import os, sys
import numpy as np
import bpy

''' + LEAVE + r'''
# A studio's own extension repository (not user_default), saved in the worker's preferences.
bpy.context.preferences.extensions.repos.new(name="Studio", module="studio", source='USER',
                                             custom_directory=os.path.join(os.path.dirname(sys.argv[2]), "studio"))
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="studio", enable_on_install=True)
bpy.ops.wm.save_userpref()
from bl_ext.studio.skin_detach_addon import api
bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
obj = bpy.context.active_object
obj.name = "scan"
api.build(obj, target_faces=150)
z = np.array([v.co.z for v in obj.data.vertices])
api.add_anchor(obj, np.flatnonzero(z < -0.7))
handle = api.add_handle(obj, np.flatnonzero(z > 0.7))
for frame, (x, angle) in ((1, (0.0, 0.0)), (30, (0.6, 0.8))):
    handle.location.x, handle.rotation_euler.y = x, angle
    handle.keyframe_insert("location", frame=frame)
    handle.keyframe_insert("rotation_euler", frame=frame)
bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 30
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
leave()
'''

BAKE_ARGS = ["--python-exit-code", "1", "--python-expr", FARM_EXPR]


@pytest.fixture(scope="module")
def worker(extension_zip, tmp_path_factory):
    """A farm worker's set-up: the extension installed in a studio repository of its own Blender
    user folder and enabled in its preferences, a saved rig
    (a sphere whose handle moves and turns over frames 1-30) and a ``blender`` stand-in. Returns
    (folder, environment, the stand-in's path, the rig's path)."""
    import bpy
    if bpy.app.version[:2] == (4, 2):  # measured with bpy 4.2.23; a real Blender 4.2 loads them at start-up
        pytest.skip("the bpy 4.2 module cannot load extensions enabled in preferences read after its import "
                    "(\"'bl_ext' is not a package\"): the worker stand-in needs bpy 5.0 or later")
    zips, _ = extension_zip
    folder = tmp_path_factory.mktemp("worker")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["BLENDER_USER_RESOURCES"] = str(folder / "user")
    (folder / "make_rig.py").write_text(MAKE_RIG)
    made = subprocess.run([sys.executable, str(folder / "make_rig.py"), str(zips[0]), str(folder / "rig.blend")],
                          cwd=folder, env=env, capture_output=True, text=True, timeout=600)
    assert made.returncode == 0, made.stdout[-2000:] + made.stderr[-2000:]
    stand_in = folder / "bin" / "blender"
    stand_in.parent.mkdir()
    stand_in.write_text(f"#!{sys.executable}\n" + BLENDER_STAND_IN)
    stand_in.chmod(0o755)
    return folder, env, stand_in, folder / "rig.blend"


def openjd_run(worker, folder, *parameters, env=None):
    """``openjd run`` of the template on the worker stand-in with the rig and ``parameters``
    ("Name=value"; chunks of 4 unless given)."""
    openjd = pathlib.Path(sys.executable).parent / "openjd"
    _, worker_env, stand_in, rig = worker
    given = {p.split("=", 1)[0] for p in parameters}
    parameters = [*parameters, *(["ChunkSize=4"] if "ChunkSize" not in given else [])]
    line = [str(openjd), "run", str(ROOT / "farm" / "openjd" / "skin_detach_bake.yaml"), "-p", f"BlendFile={rig}",
            "-p", f"BlenderExecutable={stand_in}"]
    for parameter in parameters:
        line += ["-p", parameter]
    return subprocess.run(line, cwd=folder, env=env or worker_env, capture_output=True, text=True, timeout=1200)


def test_openjd_runs_the_template_in_chunks_byte_identical_to_one_process(worker, tmp_path):
    pytest.importorskip("openjd")
    openjd = pathlib.Path(sys.executable).parent / "openjd"
    env = worker[1]
    template = ROOT / "farm" / "openjd" / "skin_detach_bake.yaml"
    check = subprocess.run([str(openjd), "check", str(template)], capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stdout + check.stderr
    run = openjd_run(worker, tmp_path, "Frames=1-30", f"OutputFolder={tmp_path / 'farm'}", "OutputFile=f_####.obj")
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "Chunks run: 9" in run.stdout and run.stdout.count("bake: error") == 0  # 8 chunks, then Verify
    assert "bake: all 30 files" in run.stdout                 # the Verify step
    one = subprocess.run([str(worker[2]), "-b", str(worker[3]), *BAKE_ARGS, "--",
                          "--frames", "1-30", "--output", str(tmp_path / "one" / "f_####.obj")],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert one.returncode == 0, one.stdout[-2000:] + one.stderr[-2000:]
    farm = {p.name: p.read_bytes() for p in (tmp_path / "farm").iterdir()}
    single = {p.name: p.read_bytes() for p in (tmp_path / "one").iterdir()}
    assert sorted(farm) == [f"f_{k:04d}.obj" for k in range(1, 31)]
    assert farm == single


def test_the_flamenco_job_types_commands_run_on_a_worker_with_only_the_extension(worker, tmp_path):
    import json
    import re
    import shutil
    node = shutil.which("node")
    if node is None:
        pytest.skip("no node to run the Flamenco job compiler stand-in")
    _, env, stand_in, rig = worker
    settings = {"frames": "1-10", "chunk_size": 5, "object": "scan", "output_folder": str(tmp_path / "bake"),
                "format": ".obj", "apply_modifiers": False, "preserve_volume": True, "blendfile": str(rig)}
    compiled = subprocess.run([node, str(ROOT / "tests" / "farm" / "flamenco_stand_in.js"),
                               str(ROOT / "farm" / "flamenco" / "skin_detach_bake.js"), json.dumps(settings), "s010"],
                              capture_output=True, text=True, timeout=60)
    assert compiled.returncode == 0, compiled.stderr
    tasks = json.loads(compiled.stdout)
    assert [t["name"] for t in tasks] == ["bake-1-5", "bake-6-10", "verify-files"]
    step = re.compile(r"(?:^|(?:render\s+\|\s+))Time: ([0-9:.]+)")  # the Worker's step counter

    def run_task(task):
        command = task["commands"][0]["parameters"]
        # The Worker runs: exe exeArgs argsBefore blendfile args, with {blender} and {blenderArgs} expanded.
        line = [str(stand_in), "-b", "-y", *command["argsBefore"], command["blendfile"], *command["args"]]
        return subprocess.run(line, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    for task in tasks[:2]:
        run = run_task(task)
        assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
        steps = [line for line in run.stdout.splitlines() if step.search(line)]
        assert len(steps) == task["commands"][0]["totalStepCount"] == 5   # a finished step per frame
    assert sorted(p.name for p in (tmp_path / "bake").iterdir()) == [f"s010_rig_{k:04d}.obj" for k in range(1, 11)]
    assert run_task(tasks[2]).returncode == 0
    (tmp_path / "bake" / "s010_rig_0007.obj").unlink()
    run = run_task(tasks[2])
    assert run.returncode == 1 and "missing (frames 7)" in run.stderr


def test_a_worker_without_the_extension_fails_its_tasks_in_flamenco_and_openjd(worker, tmp_path):
    import json
    import shutil
    _, env, stand_in, rig = worker
    env = dict(env, BLENDER_USER_RESOURCES=str(tmp_path / "bare_user"))  # a Blender with no extension
    settings = {"frames": "1-4", "chunk_size": 4, "object": "scan", "output_folder": str(tmp_path / "bake"),
                "format": ".obj", "apply_modifiers": False, "preserve_volume": True, "blendfile": str(rig)}
    node = shutil.which("node")
    if node is not None:
        compiled = subprocess.run([node, str(ROOT / "tests" / "farm" / "flamenco_stand_in.js"),
                                   str(ROOT / "farm" / "flamenco" / "skin_detach_bake.js"), json.dumps(settings), "s010"],
                                  capture_output=True, text=True, timeout=60)
        command = json.loads(compiled.stdout)[0]["commands"][0]["parameters"]
        line = [str(stand_in), "-b", "-y", *command["argsBefore"], command["blendfile"], *command["args"]]
        run = subprocess.run(line, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert run.returncode != 0 and "extension is not enabled" in run.stderr, run.stdout[-2000:] + run.stderr[-2000:]
    if (pathlib.Path(sys.executable).parent / "openjd").exists():
        run = openjd_run(worker, tmp_path, "Frames=1-4", f"OutputFolder={tmp_path / 'jd'}", "OutputFile=f_####.obj",
                         env=env)
        assert run.returncode != 0 and "extension is not enabled" in run.stdout, run.stdout[-3000:]
    assert not (tmp_path / "bake").exists() and not (tmp_path / "jd").exists()


def test_openjd_stepped_and_negative_frames_bake_and_a_blend_output_is_refused(worker, tmp_path):
    pytest.importorskip("openjd")
    # Evenly spaced frames reach the task as a stepped range ("-3-3:2"), negative ones as "-3,...".
    run = openjd_run(worker, tmp_path, "Frames=-3,-1,1,3", f"OutputFolder={tmp_path / 'out'}", "OutputFile=s_####.ply")
    assert run.returncode == 0, run.stdout[-3000:]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["s_-001.ply", "s_-003.ply", "s_0001.ply",
                                                                     "s_0003.ply"]
    run = openjd_run(worker, tmp_path, "Frames=1-4", "ChunkSize=2", f"OutputFolder={tmp_path / 'b'}",
                     "OutputFile=all.blend")
    assert run.returncode != 0 and "one .obj or .ply file per frame" in run.stdout, run.stdout[-3000:]
    assert not (tmp_path / "b" / "all.blend").exists()


def build_repo(script, out, wheels):
    return subprocess.run([sys.executable, str(script), "--platforms", "linux-x64", "--out", str(out),
                           "--wheels", str(wheels)], capture_output=True, text=True, timeout=600)


def test_build_repo_lists_the_zip_and_a_higher_version_published_into_the_same_folder(extension_zip, tmp_path):
    """`make repo`: index.json (Blender's server-generate) lists the zip by the manifest's id and
    version, its URL relative to the index, its real sha256 and size; a higher version built from
    a copy of the source into the same folder is listed alone, the older zip kept in archive/."""
    import hashlib
    import json
    import shutil
    import tomllib
    _, folder = extension_zip
    wheels, repo = folder / "wheels", tmp_path / "repo"
    first = build_repo(ROOT / "scripts" / "build_repo.py", repo, wheels)
    assert first.returncode == 0, first.stderr
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    old = repo / f"skin_detach_addon-{manifest['version']}-linux_x64.zip"
    assert "index.json" in first.stdout and old.name in first.stdout
    [entry] = json.loads((repo / "index.json").read_text())["data"]
    assert (entry["id"], entry["version"]) == (manifest["id"], manifest["version"])
    assert entry["archive_url"] == f"./{old.name}" and entry["platforms"] == ["linux-x64"]
    assert entry["archive_hash"] == "sha256:" + hashlib.sha256(old.read_bytes()).hexdigest()
    assert entry["archive_size"] == old.stat().st_size

    source = tmp_path / "source"
    for name in ("scripts", "skin_detach_addon"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    major, minor, patch = map(int, manifest["version"].split("."))
    newer = f"{major}.{minor}.{patch + 1}"
    text = (ROOT / "blender_manifest.toml").read_text()
    (source / "blender_manifest.toml").write_text(text.replace(f'version = "{manifest["version"]}"',
                                                               f'version = "{newer}"', 1))
    second = build_repo(source / "scripts" / "build_repo.py", repo, wheels)
    assert second.returncode == 0, second.stderr
    new = repo / f"skin_detach_addon-{newer}-linux_x64.zip"
    assert sorted(p.relative_to(repo).as_posix() for p in repo.rglob("*.zip")) == [
        f"archive/{old.name}", new.name]
    [entry] = json.loads((repo / "index.json").read_text())["data"]
    assert (entry["version"], entry["archive_url"]) == (newer, f"./{new.name}")
    assert entry["archive_hash"] == "sha256:" + hashlib.sha256(new.read_bytes()).hexdigest()

    again = build_repo(ROOT / "scripts" / "build_repo.py", repo, wheels)  # the older source: refused
    assert again.returncode == 1 and f"found {newer}" in again.stderr and new.exists()


def test_build_repo_fails_clearly_on_a_zip_it_cannot_read(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "skin_detach_addon-9.9.9-linux_x64.zip").write_bytes(b"not a zip")
    run = build_repo(ROOT / "scripts" / "build_repo.py", repo, tmp_path / "wheels")
    assert run.returncode == 1 and run.stderr.startswith("build_repo: error: ")
    assert "skin_detach_addon-9.9.9-linux_x64.zip: expected an extension zip" in run.stderr, run.stderr
    assert not (repo / "index.json").exists() and not (tmp_path / "wheels").exists()
