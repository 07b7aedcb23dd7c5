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
    for task in json.loads(compiled.stdout):
        args = task["commands"][0]["parameters"]["args"]
        chunk = parse_frames(args[args.index("--frames") + 1])
        assert task["commands"][0]["totalStepCount"] == len(chunk) <= size
        covered += chunk
        assert args[args.index("--modifiers") + 1] == "apply" and args[args.index("--volume") + 1] == "free"
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
    template = yaml.safe_load((ROOT / "farm" / "openjd" / "skin_detach_bake.yaml").read_text())
    openjd = template["steps"][0]["script"]["actions"]["onRun"]["args"]
    for args in (flamenco, openjd):
        # Blender exits 0 after an uncaught Python error unless --python-exit-code comes before the script.
        start = args.index("--python-expr")
        assert args[start - 2:start] == ["--python-exit-code", "1"] and args[start + 1] == FARM_EXPR
    assert "user_default" not in FARM_EXPR and "sys.exit(" in FARM_EXPR
