"""scripts/benchmark.py --quick (the 50K armadillo once per part): every figure is there and finite."""

import json
import math
import pathlib
import subprocess
import sys

import pytest

pytest.importorskip("bpy")

BENCHMARK = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "benchmark.py"


def numbers(tree, path=""):
    """Every number in a JSON tree with its path."""
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from numbers(value, f"{path}.{key}")
    elif isinstance(tree, list):
        for k, value in enumerate(tree):
            yield from numbers(value, f"{path}[{k}]")
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool):
        yield path, tree


def test_quick_benchmark_prints_tables_and_finite_figures(tmp_path):
    run = subprocess.run([sys.executable, str(BENCHMARK), "--quick", "--json", str(tmp_path / "b.json")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    for title in ("## Table 1 of the paper", "## Side by side", "## Scale", "ratios ours / Blender stack",
                  "## The modal drag at scale"):
        assert title in run.stdout
    figures = json.loads((tmp_path / "b.json").read_text())
    table1, side, scale = figures["table1"][0], figures["side"][0], figures["scale"][0]
    for key in ("build_s", "core_steps_per_s", "blender_steps_per_s", "handle_set_change_s", "peak_mb"):
        assert key in table1, key
    for method in (side["skin_detach"], side["blender_stack"], side["laplacian_whole_detail"]):
        assert set(method["quality"]) == {"edge_distortion", "dihedral_change_deg", "handle_error_pct_diag",
                                          "volume_change_pct", "rms_vs_arap_pct_diag"}
    assert side["skin_detach"]["quality"]["handle_error_pct_diag"] < 0.01  # the handle is reached exactly
    for key in ("build_s", "step_ms", "peak_mb"):
        assert key in scale, key
    large = figures["large"][0]
    assert large["vertices"] == 49990 and large["move_ms"] > 0 and large["confirm_s"] > 0
    assert large["preview_vertices"] > 0  # the quick run takes the preview path
    found = dict(numbers(figures))
    assert len(found) > 30
    bad = {path: value for path, value in found.items() if not math.isfinite(value)}
    assert not bad


def test_quality_benchmark_runs_the_pose_suite_and_the_bend_on_small_meshes(tmp_path):
    script = BENCHMARK.parent / "benchmark_quality.py"
    run = subprocess.run([sys.executable, str(script), "--meshes", "spot,cow", "--pose-meshes", "spot", "--poses", "3",
                          "--faces", "500", "--json", str(tmp_path / "q.json")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    saved = json.loads((tmp_path / "q.json").read_text())
    figures = saved["rows"]
    assert saved["meta"]["command"].startswith("python ") and "numpy" in saved["meta"]["versions"]
    assert [(r["mesh"], r["method"]) for r in figures["poses"]] == [("spot", "rotated"), ("spot", "paper")]
    rotated = figures["poses"][0]
    assert rotated["warm_converged"] == rotated["cold_converged"] == 3
    assert {r["mesh"] for r in figures["bend"]} == {"spot", "cow"}
    for row in figures["bend"]:
        assert math.isfinite(row["edge_distortion"]) and math.isfinite(row["dihedral_change_deg"])
        assert 0 <= row["creases"] < 3 * 5856
    assert "## Pose suite" in run.stdout and "creases (> 30 deg)" in run.stdout and "## Bend scenario" in run.stdout
