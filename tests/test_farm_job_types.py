"""The farm job types without a farm: the Flamenco job type's own tests under node (a stand-in
for Flamenco's job compiler), and its chunks read by the bake CLI's frame parser."""

import json
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="no node to run the Flamenco job compiler stand-in")


def test_the_flamenco_job_type_passes_its_node_tests():
    run = subprocess.run([NODE, "--test", str(ROOT / "tests" / "farm")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "# fail 0" in run.stdout


@pytest.mark.parametrize("frames, size", [("1-250", 10), ("1-30", 7), ("5-9,20,31-33", 4), ("1..12", 5)])
def test_every_chunk_parses_with_the_bake_cli_and_together_they_cover_each_frame_once(frames, size):
    pytest.importorskip("bpy")
    from skin_detach_addon.blender.baking import parse_frames
    settings = {"frames": frames, "chunk_size": size, "object": "", "output_folder": "/out", "format": ".ply",
                "apply_modifiers": True, "preserve_volume": False, "blendfile": "/shots/a.blend"}
    compiled = subprocess.run([NODE, str(ROOT / "tests" / "farm" / "flamenco_stand_in.js"),
                               str(ROOT / "farm" / "flamenco" / "skin_detach_bake.js"), json.dumps(settings)],
                              capture_output=True, text=True, timeout=60)
    assert compiled.returncode == 0, compiled.stderr
    covered = []
    for task in json.loads(compiled.stdout)[:-1]:           # the last task checks the files
        args = dict(a.split("=", 1) for a in task["commands"][0]["parameters"]["args"] if a.startswith("--") and "=" in a)
        chunk = parse_frames(args["--frames"])
        assert task["commands"][0]["totalStepCount"] == len(chunk) <= size
        covered += chunk
        assert args["--modifiers"] == "apply" and args["--volume"] == "free"
    expected = parse_frames(frames.replace("..", "-"))
    assert covered == expected and len(set(covered)) == len(covered)


def test_both_job_types_make_blender_fail_on_any_error_and_find_the_addon_in_any_repository():
    yaml = pytest.importorskip("yaml")
    from skin_detach_addon.bake_cli import FARM_EXPR
    settings = {"frames": "1-3", "chunk_size": 10, "object": "", "output_folder": "/out", "format": ".obj",
                "apply_modifiers": False, "preserve_volume": True, "blendfile": "/shots/a.blend"}
    compiled = subprocess.run([NODE, str(ROOT / "tests" / "farm" / "flamenco_stand_in.js"),
                               str(ROOT / "farm" / "flamenco" / "skin_detach_bake.js"), json.dumps(settings)],
                              capture_output=True, text=True, timeout=60)
    flamenco = json.loads(compiled.stdout)[0]["commands"][0]["parameters"]["args"]
    assert json.loads(compiled.stdout)[-1]["name"] == "verify-files"
    template = yaml.safe_load((ROOT / "farm" / "openjd" / "skin_detach_bake.yaml").read_text())
    openjd = template["steps"][0]["script"]["actions"]["onRun"]["args"]
    for args in (flamenco, openjd):
        # Blender exits 0 after an uncaught Python error unless --python-exit-code comes before the script.
        start = args.index("--python-expr")
        assert args[start - 2:start] == ["--python-exit-code", "1"] and args[start + 1] == FARM_EXPR
    assert "user_default" not in FARM_EXPR and "sys.exit(" in FARM_EXPR
    outputs = {p["name"]: p for p in template["parameterDefinitions"]}
    assert outputs["OutputFolder"]["dataFlow"] == "OUT" and outputs["OutputFolder"]["objectType"] == "DIRECTORY"
    assert [step["name"] for step in template["steps"]] == ["Bake", "Verify"]
    for args in (flamenco, openjd):                          # --name=value: a leading dash stays a value
        assert not {"--frames", "--output", "--object"} & set(args) and "--farm" in args


@pytest.mark.parametrize("text, frames", [("1-7:2", [1, 3, 5, 7]), ("1-250:5", list(range(1, 251, 5))),
                                          ("1..4", [1, 2, 3, 4]), ("-3,-2", [-3, -2]), ("-5--3", [-5, -4, -3]),
                                          ("0-10:4,20", [0, 4, 8, 20])])
def test_the_bake_cli_takes_blenders_and_openjds_range_syntax(text, frames):
    pytest.importorskip("bpy")
    from skin_detach_addon.blender.baking import parse_frames
    assert parse_frames(text) == frames



def test_a_unc_output_folder_compiles_and_fails_the_task_on_a_linux_worker_naming_the_folder(scene, tmp_path):
    # The Manager cannot know which platform a Worker runs, so the job type accepts a UNC folder; the task's own
    # bake refuses it on a Worker that cannot reach it (exit 1: Flamenco fails the task) and writes nothing.
    pytest.importorskip("bpy")
    import bpy
    import sys
    from test_blender_api import scripted_rig
    obj, _ = scripted_rig()
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "shot.blend"))
    settings = {"frames": "1-2", "chunk_size": 10, "object": obj.name, "output_folder": "\\\\server\\share\\bake",
                "format": ".obj", "apply_modifiers": False, "preserve_volume": True, "blendfile": "/shots/shot.blend"}
    compiled = subprocess.run([NODE, str(ROOT / "tests" / "farm" / "flamenco_stand_in.js"),
                               str(ROOT / "farm" / "flamenco" / "skin_detach_bake.js"), json.dumps(settings)],
                              capture_output=True, text=True, timeout=60)
    assert compiled.returncode == 0, compiled.stderr
    args = json.loads(compiled.stdout)[0]["commands"][0]["parameters"]["args"]
    task = args[args.index("--") + 1:]
    work = tmp_path / "worker"
    work.mkdir()
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake.py"), "--blend", str(tmp_path / "shot.blend"),
                          *task], capture_output=True, text=True, timeout=300, cwd=work)
    assert run.returncode == 1 and "\\\\\\\\server\\\\share\\\\bake" in run.stderr, run.stderr
    assert list(work.iterdir()) == []
