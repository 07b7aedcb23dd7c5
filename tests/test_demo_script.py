"""scripts/demo.py end to end on the 50K armadillo, a few steps and a small picture."""

import json
import math
import pathlib
import struct
import subprocess
import sys

import pytest

pytest.importorskip("bpy")

DEMO = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "demo.py"


def test_demo_writes_blend_obj_picture_and_figures(tmp_path):
    run = subprocess.run([sys.executable, str(DEMO), "--size", "50K", "--steps", "3", "--width", "480",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    figures = json.loads((tmp_path / "demo_figures.json").read_text())
    assert figures["detail_vertices"] == 49990 and 900 <= figures["proxy_faces"] <= 1200
    for key in ("build_seconds", "drag_step_ms_median", "proxy_volume_change"):
        assert math.isfinite(figures[key]), key
    assert 1.0 <= figures["proxy_least_angle"] < 60.0 and 0 <= figures["proxy_slivers"] <= 0.01 * figures["proxy_faces"]
    assert (tmp_path / "demo.blend").stat().st_size > 1e6
    obj = (tmp_path / "armadillo_deformed_0001.obj").read_text()
    assert obj.count("\nv ") == 49990
    png = (tmp_path / "demo.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">I", png[16:20])[0] == 480
    assert "ms per step in Blender" in run.stdout


def picture_is_not_blank(path):
    """A PNG that is not all background: load it with Blender and look at its pixels."""
    import bpy
    import numpy as np
    image = bpy.data.images.load(str(path))
    try:
        pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    rgb = pixels.reshape(-1, 4)[:, :3]
    return float((rgb.min(axis=1) < 0.9).mean()) > 0.05  # at least 5 % of the picture is not white


def test_tutorial_renders_its_comparison_picture(tmp_path):
    script = DEMO.parent / "tutorial.py"
    run = subprocess.run([sys.executable, str(script), "--out", str(tmp_path), "--width", "320"], capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    for name in ("compare_stack.png",):
        png = (tmp_path / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">I", png[16:20])[0] == 320
        assert picture_is_not_blank(tmp_path / name), name
