"""scripts/bake.py with the bpy module: files per frame, a baked .blend, idempotence, failures."""

import pathlib
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import quad_sphere  # noqa: E402
from test_blender_api import animate, scripted_rig  # noqa: E402

BAKE = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "bake.py"


def bake(*args):
    return subprocess.run([sys.executable, str(BAKE), *map(str, args)], capture_output=True, text=True, timeout=300)


@pytest.fixture
def rig_file(scene, tmp_path):
    obj, handle = scripted_rig()
    animate(handle, [(1, (0, 0, 0)), (4, (0.3, 0, 0.2))])
    scene.frame_start, scene.frame_end = 1, 4
    path = tmp_path / "rig.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_bake_script_writes_one_file_per_frame_and_reruns_identically(rig_file, tmp_path):
    run = bake("--blend", rig_file, "--frames", "2-3", "--output", tmp_path / "out" / "q_####.obj")
    assert run.returncode == 0, run.stderr
    first = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    assert sorted(first) == ["q_0002.obj", "q_0003.obj"]
    assert "frame 3 (2/2)" in run.stdout
    again = bake("--blend", rig_file, "--frames", "2-3", "--output", tmp_path / "out" / "q_####.obj")
    assert again.returncode == 0 and {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()} == first


def test_bake_script_saves_shape_keys_into_a_blend(rig_file, tmp_path):
    run = bake("--blend", rig_file, "--output", tmp_path / "baked.blend")  # the scene's range, 1-4
    assert run.returncode == 0, run.stderr
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "baked.blend"))
    keys = bpy.data.objects["quads"].data.shape_keys.key_blocks
    assert [k.name for k in keys][1:] == [f"skin_detach_000{f}" for f in range(1, 5)]
    top = np.empty(3 * len(keys[0].data), dtype=np.float32)
    keys["skin_detach_0004"].data.foreach_get("co", top)
    rest = np.empty_like(top)
    keys["Basis"].data.foreach_get("co", rest)
    assert np.abs(top - rest).max() > 0.2


def test_bake_script_fails_with_a_message(rig_file, tmp_path, scene):
    run = bake("--blend", rig_file, "--object", "nope", "--output", tmp_path / "x.obj")
    assert run.returncode == 1 and "--object" in run.stderr and "quads" in run.stderr
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    run = bake("--blend", rig_file, "--output", blocker / "x.obj")
    assert run.returncode == 1 and "folder" in run.stderr
    run = bake("--blend", tmp_path / "missing.blend", "--output", tmp_path / "x.obj")
    assert run.returncode == 1 and "--blend" in run.stderr
    bpy.ops.wm.read_homefile(use_empty=True)
    quad_sphere()
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "bare.blend"))
    run = bake("--blend", tmp_path / "bare.blend", "--object", "quads", "--output", tmp_path / "x.obj")
    assert run.returncode == 1 and "neither" in run.stderr
    run = bake("--blend", rig_file, "--frames", "9-1", "--output", tmp_path / "x.obj")
    assert run.returncode == 1 and "frames" in run.stderr


def test_bake_script_builds_a_missing_binding_from_the_handles(scene, tmp_path):
    from skin_detach_addon.blender import binding
    obj, handle = scripted_rig()
    animate(handle, [(1, (0, 0, 0)), (2, (0.3, 0, 0.2))])
    del obj[binding.KEY]  # a file whose binding was lost; its handles remain
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "lost.blend"))
    run = bake("--blend", tmp_path / "lost.blend", "--object", "quads", "--frames", "2", "--target-faces", 200,
               "--output", tmp_path / "found.blend")  # (writing over the source is refused: test_adversarial)
    assert run.returncode == 0, run.stderr
    assert "building the binding" in run.stdout and "binding built first" in run.stdout
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "found.blend"))
    proxies = [o for o in bpy.data.objects if "_skin_detach_proxy_of" in o]
    assert len(proxies) == 1 and binding.has_binding(bpy.data.objects["quads"])
    assert "skin_detach_0002" in bpy.data.objects["quads"].data.shape_keys.key_blocks


def test_a_frame_is_byte_identical_whichever_chunk_baked_it(rig_file, tmp_path):
    whole = bake("--blend", rig_file, "--frames", "1-4", "--output", tmp_path / "one" / "f_####.obj")
    assert whole.returncode == 0, whole.stderr
    for chunk in ("1,2", "3-4", "2-3"):
        run = bake("--blend", rig_file, "--frames", chunk, "--output", tmp_path / "chunks" / "f_####.obj")
        assert run.returncode == 0, run.stderr
    one = {p.name: p.read_bytes() for p in (tmp_path / "one").iterdir()}
    chunks = {p.name: p.read_bytes() for p in (tmp_path / "chunks").iterdir()}
    assert sorted(one) == [f"f_{k:04d}.obj" for k in range(1, 5)] and chunks == one  # no partial files left


def test_the_add_on_module_runs_the_same_bake(rig_file, tmp_path):
    code = ("import sys, bpy; sys.path.insert(0, %r); from skin_detach_addon import bake_cli; "
            "bake_cli.main(sys.argv[1:])" % str(BAKE.parent.parent))
    run = subprocess.run([sys.executable, "-c", code, "--blend", str(rig_file), "--frames", "2",
                          "--output", str(tmp_path / "m_####.obj")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    reference = bake("--blend", rig_file, "--frames", "2", "--output", tmp_path / "r_####.obj")
    assert (tmp_path / "m_0002.obj").read_bytes() == (tmp_path / "r_0002.obj").read_bytes()


def test_a_bake_killed_mid_frame_leaves_only_complete_files(rig_file, tmp_path):
    import time
    target = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, str(BAKE), "--blend", str(rig_file), "--frames", "1-4,1-4",
                                "--output", str(target / "k_####.obj")], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (target.exists() and any(target.iterdir())):
        time.sleep(0.005)
    process.kill()
    process.wait()
    reference = bake("--blend", rig_file, "--frames", "1-4", "--output", tmp_path / "whole" / "k_####.obj")
    assert reference.returncode == 0, reference.stderr
    whole = {p.name: p.read_bytes() for p in (tmp_path / "whole").iterdir()}
    visible = [p for p in target.iterdir() if not p.name.startswith(".")]
    assert all(p.read_bytes() == whole[p.name] for p in visible)  # complete, or not there at all
    again = bake("--blend", rig_file, "--frames", "1-4", "--output", target / "k_####.obj")
    assert again.returncode == 0 and {p.name: p.read_bytes() for p in target.iterdir()} == whole


@pytest.mark.parametrize("error", [ValueError("a bug"), KeyError("frame")])
def test_an_unexpected_error_exits_1_with_its_traceback(error, monkeypatch, capsys):
    from skin_detach_addon import bake_cli

    def broken(args):
        raise error
    monkeypatch.setattr(bake_cli, "run", broken)
    with pytest.raises(SystemExit) as stop:
        bake_cli.main(["--output", "out/f_####.obj"])
    assert stop.value.code == 1                               # Blender would exit 0 after an uncaught error
    err = capsys.readouterr().err
    assert "Traceback" in err and f"bake: error: unexpected {type(error).__name__}" in err


def test_a_frame_whose_file_is_missing_after_the_bake_fails_the_bake(rig_file, tmp_path, monkeypatch, capsys):
    from skin_detach_addon import api, bake_cli
    real = api.bake

    def loses_a_file(*args, **kwargs):
        records = real(*args, **kwargs)
        pathlib.Path(records[1]["output"]).unlink()           # e.g. a full disk or a cleaner on the share
        return records
    monkeypatch.setattr(api, "bake", loses_a_file)
    with pytest.raises(SystemExit) as stop:
        bake_cli.main(["--blend", str(rig_file), "--frames", "1-3", "--output", str(tmp_path / "f_####.obj")])
    assert stop.value.code == 1 and "missing frames: [2]" in capsys.readouterr().err


def test_every_baked_frame_prints_a_line_flamencos_worker_counts_as_a_step(rig_file, tmp_path):
    import re
    step = re.compile(r"(?:^|(?:render\s+\|\s+))Time: ([0-9:.]+)")  # internal/worker/command_blender.go
    run = bake("--blend", rig_file, "--frames=1-4:3", "--output", tmp_path / "s_####.obj")
    assert run.returncode == 0, run.stderr
    assert len([line for line in run.stdout.splitlines() if step.search(line)]) == 2  # frames 1 and 4
    assert sorted(p.name for p in tmp_path.glob("s_*.obj")) == ["s_0001.obj", "s_0004.obj"]


def test_a_farm_chunk_refuses_a_blend_and_verify_names_the_missing_frames(rig_file, tmp_path):
    run = bake("--blend", rig_file, "--frames=1-2", "--output", tmp_path / "all.blend", "--farm")
    assert run.returncode == 1 and "one .obj or .ply file per frame" in run.stderr
    assert not (tmp_path / "all.blend").exists()
    run = bake("--blend", rig_file, "--frames=-1,0", "--output", tmp_path / "v_####.obj", "--farm")
    assert run.returncode == 0, run.stderr                   # negative frames, passed as --frames=
    assert bake("--blend", rig_file, "--frames=-1,0", "--output", tmp_path / "v_####.obj", "--verify").returncode == 0
    (tmp_path / "v_-001.obj").unlink()
    run = bake("--blend", rig_file, "--frames=-1,0", "--output", tmp_path / "v_####.obj", "--verify")
    assert run.returncode == 1 and "1 are missing (frames -1)" in run.stderr


def test_two_bakes_of_one_frame_into_one_folder_do_not_collide(rig_file, tmp_path, monkeypatch):
    """A second bake of the frame (a requeued task whose first Worker still runs) finishes while
    the first one is exporting: neither may take or rename the other's partial file."""
    from skin_detach_addon import api
    from skin_detach_addon.blender import baking, mesh_io
    bpy.ops.wm.open_mainfile(filepath=str(rig_file))
    obj = bpy.data.objects["quads"]
    export = baking._FileWriter._export
    pattern = str(tmp_path / "c_####.obj")
    inner = []

    def meanwhile(writer, path, obj_format):
        export(writer, path, obj_format)
        if not inner:                                         # the other bake writes the same frame now
            inner.append(None)
            inner[0] = baking._FileWriter(obj, pattern, False).write(2, mesh_io.read_positions(obj.data))
    monkeypatch.setattr(baking._FileWriter, "_export", meanwhile)
    records = api.bake(obj, [2], into=api.FILES, path=pattern)
    assert inner == [records[0]["output"]] and (tmp_path / "c_0002.obj").stat().st_size > 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no partial file left


def test_ctrl_c_stops_a_bake_with_complete_files_and_exit_130(rig_file, tmp_path):
    import signal
    import time
    target = tmp_path / "i_####.obj"
    process = subprocess.Popen([sys.executable, str(BAKE), "--blend", str(rig_file), "--frames", "1-2000",
                                "--output", str(target)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not process.stdout.readline().startswith("Time:"):
        pass                                                  # the bake is under way
    process.send_signal(signal.SIGINT)
    try:
        _, err = process.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail("Ctrl-C did not stop the bake")
    assert process.returncode == 130 and "interrupted" in err, err[-2000:]
    written = sorted(tmp_path.glob("i_*.obj"))
    assert 0 < len(written) < 2000 and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("output", [r"\\server\share\bake\q_####.obj", "C:/bake/q_####.obj", r"bake\q_####.obj"])
def test_a_windows_output_fails_on_this_machine_naming_the_folder_and_writes_nothing(rig_file, tmp_path, output):
    # A Flamenco job type passes a UNC folder through (a Windows Worker reaches it); a Linux Worker must fail the
    # task instead of baking into a folder of its own disk named like the share and reporting success.
    work = tmp_path / "work"
    work.mkdir()
    run = subprocess.run([sys.executable, str(BAKE), "--blend", str(rig_file), "--frames", "2", "--output", output],
                         capture_output=True, text=True, timeout=300, cwd=work)
    assert run.returncode == 1 and repr(output) in run.stderr and "Windows path" in run.stderr, run.stderr
    assert list(work.iterdir()) == []


def test_paths_of_the_other_platform_are_refused_on_each_platform():
    from skin_detach_addon.blender.baking import check_reachable
    from skin_detach_addon.core.errors import SkinDetachError
    for path in ("/mnt/render/q_####.obj", "out/q.obj", "q.ply"):
        check_reachable("--output", path, platform="posix")
    for path in (r"\\server\share\q.obj", r"C:\bake\q.obj", "d:/q.obj", r"out\q.obj"):
        with pytest.raises(SkinDetachError, match="--output: expected a folder this machine can reach"):
            check_reachable("--output", path, platform="posix")
    for path in (r"\\server\share\q.obj", "//server/share/q.obj", r"C:\bake\q.obj", "out/q.obj"):
        check_reachable("--output", path, platform="nt")
    with pytest.raises(SkinDetachError, match="a POSIX path"):
        check_reachable("--output", "/mnt/render/q.obj", platform="nt")
