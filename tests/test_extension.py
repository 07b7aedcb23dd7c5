"""scripts/build_extension.py: the linux-x64 zip builds, validates, installs into an isolated
Blender user folder and runs Build + Apply through the installed copy (downloads wheels)."""

import base64
import csv
import hashlib
import io
import os
import pathlib
import re
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


SCIPY_TESTS = re.compile(r"scipy/(?:.+/)?tests/")

#: Run with the slimmed scipy first on the path: the modules the add-on imports, a sparse solve, a
#: shortest path and a KD-tree query.
USE_SCIPY = r"""
import sys
import numpy as np
import scipy, scipy.linalg, scipy.sparse, scipy.sparse.csgraph, scipy.sparse.linalg, scipy.spatial
assert scipy.__file__.startswith(sys.argv[1]), scipy.__file__
A = scipy.sparse.diags_array([-np.ones(4), 2 * np.ones(5), -np.ones(4)], offsets=[-1, 0, 1], format="csc")
x = scipy.sparse.linalg.spsolve(A, np.ones(5))
assert np.allclose(A @ x, 1.0), x
assert scipy.sparse.csgraph.shortest_path(A != 0, unweighted=True)[0, 4] == 4
distance, index = scipy.spatial.cKDTree(np.eye(3)).query([0.9, 0.0, 0.0])
assert index == 0 and abs(distance - 0.1) < 1e-12, (distance, index)
print("slim scipy works")
"""


def wheel_records(wheel):
    """{file name: (RECORD's hash, RECORD's size)} of a wheel (a ZipFile) and the name of its RECORD."""
    [record] = [n for n in wheel.namelist() if re.fullmatch(r"[^/]+\.dist-info/RECORD", n)]
    rows = list(csv.reader(io.StringIO(wheel.read(record).decode())))
    return {row[0]: (row[1], row[2]) for row in rows if row}, record


def test_the_zips_scipy_wheels_leave_out_scipys_tests_stay_valid_and_import(extension_zip, tmp_path):
    """Each scipy wheel in the zip is the download less scipy's test suites (same file name, every
    other entry byte for byte), its RECORD lists exactly the files kept with their real sha256 and
    sizes; the download in the cache keeps its tests; the wheel for this Python installs with pip
    and scipy's sparse solve, graph and KD-tree run from it."""
    zips, folder = extension_zip
    with zipfile.ZipFile(zips[0]) as archive:
        wheels = {n.split("/", 1)[1]: archive.read(n) for n in archive.namelist() if n.startswith("wheels/")}
    scipy_wheels = sorted(n for n in wheels if n.startswith("scipy-"))
    assert len(scipy_wheels) == 3
    for name, data in wheels.items():
        with zipfile.ZipFile(io.BytesIO(data)) as wheel, zipfile.ZipFile(folder / "wheels" / name) as download:
            names = wheel.namelist()
            assert not [n for n in names if SCIPY_TESTS.match(n)], name
            left_out = [n for n in download.namelist() if SCIPY_TESTS.match(n)]
            assert bool(left_out) == name.startswith("scipy-"), (name, len(left_out))
            assert names == [n for n in download.namelist() if n not in left_out]
            assert all(wheel.getinfo(n).CRC == download.getinfo(n).CRC for n in names if not n.endswith("/RECORD"))
            records, record = wheel_records(wheel)
            assert records.pop(record) == ("", "")
            files = {n for n in names if not n.endswith("/")} - {record}
            assert set(records) == files, (name, sorted(set(records) ^ files)[:5])
            for member, (digest, size) in records.items():
                content = wheel.read(member)
                expected = base64.urlsafe_b64encode(hashlib.sha256(content).digest()).rstrip(b"=").decode()
                assert (digest, size) == ("sha256=" + expected, str(len(content))), (name, member)
            if name.startswith("scipy-"):
                assert "scipy/_lib/_testutils.py" in names  # scipy/__init__ imports it
                assert set(wheel_records(download)[0]) - set(records) - {record} == {
                    n for n in left_out if not n.endswith("/")}

    tag = "cp%d%d" % sys.version_info[:2]
    mine = [n for n in scipy_wheels if f"-{tag}-" in n]
    if not mine:
        pytest.skip(f"the zip has no scipy wheel for this Python ({tag}) to install")
    (tmp_path / mine[0]).write_bytes(wheels[mine[0]])
    target = tmp_path / "site"
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", "--no-compile",
                          "--target", str(target), str(tmp_path / mine[0])],
                         capture_output=True, text=True, timeout=600)
    assert pip.returncode == 0, pip.stdout + pip.stderr
    assert not list(target.glob("scipy/**/tests"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(target)
    run = subprocess.run([sys.executable, "-c", USE_SCIPY, str(target)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and "slim scipy works" in run.stdout, run.stdout + run.stderr


def test_slimming_refuses_a_wheel_whose_record_disagrees_with_its_content(tmp_path):
    import importlib.util
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    build_extension = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_extension)
    source = tmp_path / "scipy-1.0-cp311-cp311-any.whl"
    files = {"scipy/__init__.py": b"x = 1\n", "scipy/tests/test_x.py": b"", "scipy/sub/tests/data.txt": b"t",
             "scipy/sub/tests.py": b"y = 2\n"}
    record = "".join(f"{n},{build_extension.record_hash(d)},{len(d)}\n" for n, d in files.items())
    with zipfile.ZipFile(source, "w") as wheel:
        for name, data in files.items():
            wheel.writestr(name, data)
        wheel.writestr("scipy-1.0.dist-info/RECORD", record + "scipy-1.0.dist-info/RECORD,,\n")
    slim = tmp_path / "slim.whl"
    assert build_extension.slim_wheel(source, slim, build_extension.LEFT_OUT["scipy"]) == 2
    with zipfile.ZipFile(slim) as wheel:
        assert wheel.namelist() == ["scipy/__init__.py", "scipy/sub/tests.py", "scipy-1.0.dist-info/RECORD"]
        kept = {n: build_extension.record_hash(files[n]) for n in ("scipy/__init__.py", "scipy/sub/tests.py")}
        assert wheel.read("scipy-1.0.dist-info/RECORD").decode().splitlines() == [
            f"scipy/__init__.py,{kept['scipy/__init__.py']},6", f"scipy/sub/tests.py,{kept['scipy/sub/tests.py']},6",
            "scipy-1.0.dist-info/RECORD,,"]
    with zipfile.ZipFile(source, "a") as wheel:
        wheel.writestr("scipy/extra.py", b"")  # a file its RECORD does not list
    with pytest.raises(build_extension.BuildFailed, match="scipy/extra.py as its RECORD lists it, None"):
        build_extension.slim_wheel(source, slim, build_extension.LEFT_OUT["scipy"])


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
