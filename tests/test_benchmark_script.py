"""scripts/benchmark_scale.py --quick (the 50K armadillo once per part) and benchmark_quality.py on small
meshes: every figure is there and finite."""

import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")

BENCHMARK = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "benchmark_scale.py"


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
    for title in ("### Table 1 of the paper", "### Side by side", "Ratios ours / Blender's stack",
                  "of which the stretch attribute", "### The modal drag at scale"):
        assert title in run.stdout
    saved = json.loads((tmp_path / "b.json").read_text())
    assert saved["meta"]["command"].startswith("python ") and "bpy" in saved["meta"]["versions"]
    # The add-on ran as an artist has it (registered, its handlers installed) in every part.
    assert saved["meta"]["registered"] is True
    assert all(row["registered"] is True for rows in saved["rows"].values() for row in rows)
    figures = saved["rows"]
    table1, side = figures["table1"][0], figures["side"][0]
    for key in ("build_s", "blender_steps_per_s", "peak_mb"):
        assert key in table1, key
    assert table1["handles_s"] > 0  # adding the anchor and the handle prepared their layouts
    for method in (side["skin_detach"], side["blender_stack"], side["laplacian_whole_detail"]):
        assert set(method["quality"]) == {"edge_distortion", "dihedral_change_deg", "creases", "handle_error_pct_diag",
                                          "volume_change_pct", "rms_vs_arap_pct_diag"}
    assert side["skin_detach"]["quality"]["handle_error_pct_diag"] < 0.01  # the handle is reached exactly
    assert set(side["ratios"]) == {"setup", "step"}
    ours = side["skin_detach"]
    assert ours["setup_s"] > ours["build_s"] > 0 and ours["setup_s"] > ours["handles_s"] > 0  # both counted
    settle = side["skin_detach"]["settle"]
    assert 0 < settle["stretch_s"] < settle["settle_s"]  # the stretch attribute was written, and timed
    large = figures["large"][0]
    assert large["vertices"] == 49990 and all(d["move_ms"] > 0 for d in large["drags"])
    assert all(d["first_move_ms"] > 0 for d in large["drags"])
    assert [d["drag"] for d in large["drags"]] == ["first drag", "same handle again", "second handle"]
    assert [d["handles_s"] is None for d in large["drags"]] == [False, True, False]  # Add Handle timed
    assert all(0 < d["stretch_s"] < d["confirm_s"] for d in large["drags"])
    assert large["preview_vertices"] > 0  # the quick run takes the preview path
    quads = figures["files"][0]                          # the files part: a quad mesh, 300K
    assert "### The bound file: triangles and quads" in run.stdout
    assert quads["faces"] == "quads" and quads["vertices"] == 299_930 and quads["size"] == "300K-quads"
    assert 1.0 < quads["files"]["size_x"] == quads["files"]["blend_mb"] / quads["files"]["plain_mb"] < 2.0
    # The add-on asks for min(60,000, an eighth of the mesh) preview vertices; the clustering's
    # repair keeps the quad mesh's preview near that.
    assert 0.8 * (299_930 // 8) <= quads["preview_vertices"] <= 1.25 * (299_930 // 8)
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
    assert saved["meta"]["registered"] is True  # the bend as a script makes it: the add-on registered
    assert [(r["mesh"], r["method"]) for r in figures["poses"]] == [("spot", "rotated"), ("spot", "paper")]
    rotated = figures["poses"][0]
    assert rotated["warm_converged"] == rotated["cold_converged"] == 3
    assert {r["mesh"] for r in figures["bend"]} == {"spot", "cow"}
    for row in figures["bend"]:
        assert math.isfinite(row["edge_distortion"]) and math.isfinite(row["dihedral_change_deg"])
        assert 0 <= row["creases"] < 3 * 5856
    scripted = [r for r in figures["bend"] if r["method"] == "add-on (api.deform)"]
    assert len(scripted) == 2
    for row in scripted:  # the empty sits at its selection's median point; the add-on meets its handle
        assert 0 <= row["pivot_offset_diag"] < 1e-4 and row["handle_error_pct_diag"] < 1e-3
        assert row["stretch_max"] > row["stretch_mean"] > 0
    assert "pivot offset (diag)" in run.stdout
    assert "## Pose suite" in run.stdout and "creases (> 30 deg)" in run.stdout and "## Bend scenario" in run.stdout


def test_quality_benchmark_rigs_option_measures_every_rig_on_a_small_mesh(tmp_path):
    script = BENCHMARK.parent / "benchmark_quality.py"
    run = subprocess.run([sys.executable, str(script), "--rigs", "spot", "--rig-faces", "300", "--face-handles", "6",
                          "--face-drags", "2", "--moves", "3", "--json", str(tmp_path / "r.json")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "## Rigs artists build" in run.stdout and "## Pose suite" not in run.stdout
    for goal in ("worst off (goal <= 1e-5)", "(<= 1e-5)", "move ms median (<= 16)", "(<= 150)", "(<= 0.5)"):
        assert goal in run.stdout, goal
    saved = json.loads((tmp_path / "r.json").read_text())
    assert saved["meta"]["command"].startswith("python ") and "bpy" in saved["meta"]["versions"]
    assert saved["meta"]["registered"] is True  # the add-on as an artist has it
    rows = saved["rows"]["rigs"]
    assert [r["rig"] for r in rows] == ["limb: 3 adjacent handles + shoulder anchor",
                                        "hand parented to the forearm's empty", "weighted vertex groups (overlapping)",
                                        "face rig: 6 small handles"]
    for row in rows:
        assert row["mesh"] == "spot" and row["target_faces"] == 300 and "refused" not in row
        assert row["worst_off"] >= 0 and row["worst_anchor"] >= 0 and row["move_ms_median"] > 0
        assert row["confirm_ms_max"] >= row["confirm_ms_median"] > 0
        assert len(row["per_handle"]) == row["handles"] + row["anchors"]
    assert [(r["handles"], r["anchors"]) for r in rows] == [(3, 1), (3, 1), (2, 1), (6, 1)]
    face = rows[-1]
    assert face["add_handle_s_max"] >= face["add_handle_s_median"] > 0
    bad = {path: value for path, value in numbers(rows) if not math.isfinite(value)}
    assert not bad


def test_drag_benchmark_busy_option_spins_a_core_beside_each_drag_and_saves_a_busy_row(tmp_path):
    script = BENCHMARK.parent / "benchmark_drag.py"
    run = subprocess.run([sys.executable, str(script), "--meshes", "spot", "--faces", "300", "--moves", "3",
                          "--rest-ms", "20", "--busy", "--busy-rest-ms", "40", "--json", str(tmp_path / "d.json")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "| spot (busy) |" in run.stdout and "## With one core busy" in run.stdout and "40 ms of rest" in run.stdout
    saved = json.loads((tmp_path / "d.json").read_text())
    assert "--busy" in saved["meta"]["command"] and saved["meta"]["registered"] is True
    [row] = saved["rows"]
    quiet, busy = row, row["busy"]
    for figures in (quiet, busy):
        assert figures["move_ms_median"] > 0 and figures["tracking_median"] >= 0 and figures["path_ratio"] > 0
        assert figures["load"] >= 0 and figures["release_pop"] >= 0 and figures["confirm_ms"] > 0
        assert figures["registered"] and figures["live_update_runs"] == 0  # as an artist has it; live update keeps out
    assert "stack" not in busy and set(busy["fails"]) <= {"pop", "tracking", "path", "confirm"}
    assert busy["worst"] > 0
    bad = {path: value for path, value in numbers(row) if not math.isfinite(value)}
    assert not bad
    # The page shows the busy rows under the quiet table.
    (tmp_path / "results").mkdir()
    (tmp_path / "d.json").rename(tmp_path / "results" / "drag.json")
    page = subprocess.run([sys.executable, str(BENCHMARK.parent / "benchmark_page.py"), "--results",
                           str(tmp_path / "results"), "--out", str(tmp_path / "b.md")], capture_output=True, text=True)
    assert page.returncode == 0, page.stderr
    text = (tmp_path / "b.md").read_text()
    assert text.index("| spot | ") < text.index("### With one core busy") < text.rindex("| spot | ")


def test_the_spinner_keeps_a_core_busy_while_the_block_runs_and_is_killed_after_it():
    sys.path.insert(0, str(BENCHMARK.parent))
    try:
        import benchmark_drag
    finally:
        sys.path.remove(str(BENCHMARK.parent))
    with benchmark_drag.spinning(False) as none:
        assert none is None
    with benchmark_drag.spinning(True) as spinner:
        assert spinner.poll() is None                       # spinning
        stat = pathlib.Path(f"/proc/{spinner.pid}/stat")
        if stat.exists():                                   # Linux: it burns CPU time, not sleeps
            assert int(stat.read_text().rsplit(")", 1)[1].split()[11]) > 0
    assert spinner.poll() is not None                       # killed at the end
    with pytest.raises(RuntimeError):
        with benchmark_drag.spinning(True) as spinner:
            raise RuntimeError("a failed drag")
    assert spinner.poll() is not None                       # killed when the block raised, too


def test_quality_benchmark_proxy_angles_option_measures_the_proxy_beside_decimate(tmp_path):
    script = BENCHMARK.parent / "benchmark_quality.py"
    run = subprocess.run([sys.executable, str(script), "--proxy-angles", "--meshes", "cow", "--sizes", "3000,12000",
                          "--json", str(tmp_path / "a.json")], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "## Proxy triangles" in run.stdout and "## Pose suite" not in run.stdout and "goals met on" in run.stdout
    rows = json.loads((tmp_path / "a.json").read_text())["rows"]["proxy_angles"]
    assert [r["mesh"] for r in rows] == ["cow", "cow", "armadillo (demo 300K)"]
    assert rows[0]["vertices"] >= 3000 and rows[1]["vertices"] >= 12000 > rows[0]["vertices"]
    for row in rows:
        assert 0.0 <= row["least"] <= 60.0 <= row["largest"] <= 180.0 and 0 <= row["under_10_pct"] <= 100
        assert isinstance(row["goals_met"], bool)
        assert row["decimate"]["faces"] > 0 and math.isfinite(row["decimate"]["least"])
    assert rows[-1]["vertices"] == 299930


def test_riders_benchmark_measures_each_part_beside_blenders_stack(tmp_path):
    script = BENCHMARK.parent / "benchmark_riders.py"
    run = subprocess.run([sys.executable, str(script), "--meshes", "cow", "--at-least", "3000", "--faces", "300",
                          "--moves", "5", "--several", "", "--json", str(tmp_path / "r.json")], capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "## Riders and several objects" in run.stdout
    saved = json.loads((tmp_path / "r.json").read_text())
    assert saved["meta"]["registered"] is True  # the add-on as an artist has it
    rows = saved["rows"]["riders"]
    setups = [row["setup"] for row in rows]
    assert setups[0] == "one mesh" and setups[-1] == "Blender stack"
    ours = rows[0]
    assert (ours["parts"], ours["riders"]) == (5, 3)  # the body, three riders and the prop apart
    for kind in ("eye", "plate", "bracelet", "far"):
        for pose in ("bend", "drag"):
            assert all(math.isfinite(value) for value in ours[pose][kind].values())
    assert ours["bend"]["far"]["displaced"] <= 1e-6 and ours["drag"]["far"]["displaced"] <= 1e-6
    assert ours["bend"]["eye"]["offset"] < 0.5 * ours["bend"]["eye"]["moved"]  # it followed the head
    assert ours["handle_error"] <= 1e-5 and ours["anchor_error"] <= 1e-5
    assert run.stdout.count("| cow |") == 4 * len(rows)


def test_quality_benchmark_repair_compare_option_builds_each_mesh_with_and_without_the_repair(tmp_path):
    script = BENCHMARK.parent / "benchmark_quality.py"
    run = subprocess.run([sys.executable, str(script), "--repair-compare", "--meshes", "cow,rod-0.05,sheet",
                          "--at-least", "0", "--faces", "300", "--json", str(tmp_path / "r.json")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "## Sliver repair on vs off" in run.stdout and "## Pose suite" not in run.stdout
    assert "slowest build with the repair" in run.stdout and "more creases with the repair on" in run.stdout
    rows = json.loads((tmp_path / "r.json").read_text())["rows"]["repair_compare"]
    assert [r["mesh"] for r in rows] == ["cow", "rod-0.05", "sheet"]
    assert [r["vertices"] for r in rows] == [2903, 4826, 3721]  # as they are (--at-least 0), rods and sheet made
    for row in rows:
        on, off = row["on"], row["off"]
        assert row["target"] == 300 and on["build_s"] > 0 and off["build_s"] > 0 and on["repair_s"] >= 0
        assert off["angle_rows"] == off["passes"] == 0 < on["angle_rows"]  # off: the proxy as simplified
        assert on["least"] >= off["least"] and on["slivers"] <= off["slivers"]
        assert on["faces"] >= 0.95 * 300 or on["short"]
        assert on["creases"] >= 0 and off["creases"] >= 0
        assert f"| {row['mesh']} | {row['vertices']:,} |" in run.stdout


def right_triangles(angles_degrees):
    """Triangles (k, 3) over points (3k, 3): one right triangle per angle, that angle at its first
    corner, 90 degrees at its second."""
    points, triangles = [], []
    for k, angle in enumerate(angles_degrees):
        points += [(0.0, 0.0, k), (1.0, 0.0, k), (1.0, np.tan(np.radians(angle)), k)]
        triangles.append((3 * k, 3 * k + 1, 3 * k + 2))
    return np.array(points), np.array(triangles)


@pytest.mark.parametrize("angles, least, under_10_pct, under_1, met", [
    ([45.0] * 100, 45.0, 0.0, 0, True),               # no thin face
    ([45.0] * 99 + [5.0], 5.0, 1.0, 0, True),        # 1 % of the faces under 10 degrees: the limit
    ([45.0] * 98 + [5.0] * 2, 5.0, 2.0, 0, False),   # 2 %: over it
    ([45.0] * 199 + [0.5], 0.5, 0.5, 1, False),      # a face under 1 degree
])
def test_proxy_angle_figures_count_thin_faces_against_the_goals(angles, least, under_10_pct, under_1, met):
    sys.path.insert(0, str(BENCHMARK.parent))
    try:
        import benchmark_quality
    finally:
        sys.path.remove(str(BENCHMARK.parent))
    figures = benchmark_quality.angle_figures(*right_triangles(angles))
    assert figures["least"] == pytest.approx(least) and figures["largest"] == pytest.approx(90.0)
    assert figures["under_10_pct"] == pytest.approx(under_10_pct) and figures["under_1"] == under_1
    assert figures["over_170"] == 0 and figures["goals_met"] is met
