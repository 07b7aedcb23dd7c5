"""The tutorial's comparison picture, rendered from the bundled armadillo (bpy module):

    python scripts/tutorial.py [--out docs]

docs/compare_stack.png: the bend scenario (DESIGN section 4) at rest, with Skin Detach, and with
Blender's own stack (Decimate to the same face count + Hook + Laplacian Deform + Surface Deform),
with each result's edge distortion and dihedral change. The tutorial's steps are pictured in a
real Blender window by ``make docs-pictures`` (docs/window_*.png).
"""

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench import blender_stack  # noqa: E402
from bench.meshes import ROOT, blender_mesh, bundled  # noqa: E402
from bench.quality import dihedral_change, edge_distortion  # noqa: E402
from bench.render import colour_object, render_row  # noqa: E402
from bench.scenario import bend_scenario  # noqa: E402

import bpy  # noqa: E402
from mathutils import Matrix  # noqa: E402

from skin_detach_addon import api  # noqa: E402

GREY = (0.72, 0.72, 0.72, 1)


def copy_of(obj, name, points=None):
    """A plain copy of ``obj``'s mesh (no binding), at ``points`` if given, linked to the scene."""
    mesh = obj.data.copy()
    if points is not None:
        mesh.vertices.foreach_set("co", np.asarray(points, dtype=np.float32).ravel())
        mesh.update()
    out = bpy.data.objects.new(name, mesh)
    out.matrix_world = obj.matrix_world.copy()
    bpy.context.scene.collection.objects.link(out)
    return out


def positions(obj):
    out = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
    obj.data.vertices.foreach_get("co", out)
    return out.reshape(-1, 3).astype(np.float64)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(ROOT / "docs"))
    parser.add_argument("--width", type=int, default=1600)
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    points, triangles = bundled("armadillo")
    scenario = bend_scenario(points)

    bpy.ops.wm.read_homefile(use_empty=True)
    obj = blender_mesh("armadillo", points, triangles)
    stats = api.build(obj, target_faces=1000)
    api.add_anchor(obj, scenario.anchor_ids)
    grip = api.add_handle(obj, scenario.handle_ids)
    grip.matrix_world = Matrix((scenario.motion(1.0) @ np.array(grip.matrix_world)).tolist())
    api.deform(obj)
    ours = copy_of(obj, "ours", positions(obj))
    colour_object(ours, (0.45, 0.65, 0.9, 1))
    rest = copy_of(obj, "rest", points)
    colour_object(rest, GREY)
    figures, stack, empty = blender_stack.build_stack(points, triangles, scenario, stats["proxy_faces"])
    bpy.data.objects["stack_proxy"].hide_render = True
    empty.matrix_world = Matrix(scenario.motion(1.0).tolist())
    bpy.context.view_layer.update()
    columns = [[rest], [ours]]
    labels = ["rest", f"Skin Detach\nedge {edge_distortion(points, positions(ours), triangles):.3f}, "
                      f"dihedral {dihedral_change(points, positions(ours), triangles):.2f} deg"]
    if figures["bound"]:
        result = blender_stack.evaluated_positions(stack)
        colour_object(stack, (0.55, 0.8, 0.55, 1))
        columns.append([stack])
        labels.append(f"Blender stack\nedge {edge_distortion(points, result, triangles):.3f}, "
                      f"dihedral {dihedral_change(points, result, triangles):.2f} deg")
    else:
        stack.hide_render = True
    engine = render_row(columns, labels, out / "compare_stack.png", args.width)
    print(f"tutorial: {engine}; wrote {out / 'compare_stack.png'}")


if __name__ == "__main__":
    main()
