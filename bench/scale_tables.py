"""The scale benchmark's tables in Markdown, from its figures (the rows scripts/benchmark_scale.py
measures and saves): the script prints them as it measures, scripts/benchmark_page.py puts them
on docs/benchmarks.md under the command that measured them."""

from bench.report import table

#: A drag of the large part, in the order it runs.
DRAGS = "first, again, 2nd handle"


def number(value, text):
    """``text`` (a format of ``value``), or "-" where there is no value (None or nan)."""
    return "-" if value is None or value != value else text.format(value)


def table1(rows):
    return ("\n### Table 1 of the paper\n\nBundled meshes flat-subdivided towards the paper's sizes, proxies of the "
            "paper's vertex counts. Build is api.build; then the bend's anchor and handle are added, each add "
            "preparing its layout (api.prepare); a drag step is Deformation.step as the modal drag steps "
            "(write-back and depsgraph update included).\n\n" + table([
                ("model (ours)", lambda r: r["name"]), ("vertices", lambda r: f"{r['vertices']:,}"),
                ("proxy vertices / faces", lambda r: f"{r['proxy_vertices']:,} / {r['proxy_faces']:,}"),
                ("build s", lambda r: f"{r['build_s']:.2f}"),
                ("anchor + handle added s", lambda r: f"{r['handles_s']:.2f}"),
                ("drag steps/s", lambda r: f"{r['blender_steps_per_s']:.0f}"),
                ("peak MB", lambda r: f"{r['peak_mb']:.0f}"),
                ("paper: model, vertices, proxy vertices, FPS, precompute",
                 lambda r: ", ".join(str(x) for x in r["paper"]))], rows))


def side(row):
    ours, stack, single = row["skin_detach"], row["blender_stack"], row.get("laplacian_whole_detail")
    methods = [dict(name="Skin Detach (api.build, anchor and handle added; drag step with write-back)",
                    setup=ours["setup_s"], ms=ours["step_ms"], q=ours["quality"])]
    if stack.get("bound"):
        methods.append(dict(name=f"Blender: Decimate ({stack['proxy_faces']} faces) + Hook + Laplacian Deform + "
                                 f"Surface Deform", setup=stack["decimate_s"] + stack["bind_s"],
                            ms=stack["frame_ms"], q=stack["quality"]))
    if single and single.get("bound"):
        methods.append(dict(name="Blender: Hook + Laplacian Deform on the whole detail", setup=single["bind_s"],
                            ms=single["frame_ms"], q=single["quality"]))
    ratios = (f"Ratios ours / Blender's stack: set-up {row['ratios']['setup']:.2f}, per step "
              f"{row['ratios']['step']:.2f}." if "ratios" in row else "Blender's stack: Surface Deform did not bind.")
    if single and single.get("bound"):
        ratios += f" Ours / Laplacian Deform on the whole detail per step: {ours['step_ms'] / single['frame_ms']:.2f}."
    settle = ours["settle"]
    return (f"\n### Side by side, bend scenario, armadillo {row['vertices']:,} vertices, {row['steps']} steps\n\n"
            "Set-up: api.build and the anchor and handle added (each preparing its layout) against Decimate + "
            "Laplacian Deform and Surface Deform bind; per step: a drag step against a frame of the stack with its "
            "hook moved.\n\n" + table([
                ("method", lambda m: m["name"]), ("set-up s", lambda m: f"{m['setup']:.2f}"),
                ("per step / frame ms", lambda m: f"{m['ms']:.1f}"),
                ("edge distortion", lambda m: f"{m['q']['edge_distortion']:.3f}"),
                ("dihedral change deg", lambda m: f"{m['q']['dihedral_change_deg']:.2f}"),
                ("creases (> 30 deg)", lambda m: str(m["q"]["creases"])),
                ("handle error % diag", lambda m: f"{m['q']['handle_error_pct_diag']:.2f}"),
                ("volume change %", lambda m: number(m["q"]["volume_change_pct"], "{:+.2f}")),
                ("RMS vs ARAP % diag", lambda m: number(m["q"].get("rms_vs_arap_pct_diag"), "{:.2f}"))], methods) +
            f"\n{ratios} Ours: api.build {ours['build_s']:.2f} s, the anchor and handle added {ours['handles_s']:.2f} "
            f"s. The settled step (a confirm's write) took {settle['settle_s']:.3f} s, of which the stretch attribute "
            f"{settle['stretch_s']:.3f} s ({settle['stretch_pct']:.1f} %).\n")


def large(rows):
    def each(key, text):
        return lambda r: ", ".join(number(d.get(key), text) for d in r["drags"])
    return ("\n### The modal drag at scale\n\nDragSession as the modal operator drives it (fake top view, 1,000-face "
            "proxy target), Blender's depsgraph update after every mouse move. Build is api.build's blocking time; "
            "ready, from the build's start, when its background job (the full-detail rebuild of meshes of a million "
            "vertices or more) is done, Add Anchor and Add Handle running beside it. Then three drags, each "
            "confirmed: the first (the bend's anchor and handle), the same handle again, and a second handle added "
            "about the middle (Add Handle prepares its layout; then its layout's first confirm). Per drag, in that "
            "order: the seconds adding its handles, the first and the median move, the moves' 95th percentile, the "
            "seconds waited before the confirm for what a background thread still made for the layout (the "
            "moves here are quicker than an artist's drag), the confirm and the stretch attribute's share of it; "
            "api.deform after a script moves the last handle."
            "\n\n" + table([
                ("vertices", lambda r: f"{r['vertices']:,}"), ("proxy faces", lambda r: f"{r['proxy_faces']:,}"),
                ("preview vertices", lambda r: f"{r['preview_vertices']:,}"),
                ("build s", lambda r: f"{r['build_s']:.2f}"),
                ("build stages s", lambda r: ", ".join(f"{k} {v:.1f}" for k, v in r["build_stages_s"].items())),
                ("build adds MB to peak", lambda r: f"{r['build_peak_mb_added']:.0f}"),
                ("ready s", lambda r: number(r.get("ready_s"), "{:.1f}")),
                ("Add Anchor, Add Handle s", lambda r: ", ".join(number(r.get(k), "{:.2f}")
                                                                 for k in ("anchor_s", "handle_s"))),
                (f"handles added s ({DRAGS})", each("handles_s", "{:.2f}")),
                (f"first move ms ({DRAGS})", each("first_move_ms", "{:.1f}")),
                (f"move ms median ({DRAGS})", each("move_ms", "{:.1f}")),
                (f"move ms p95 ({DRAGS})", each("move_p95_ms", "{:.1f}")),
                (f"waited s before the confirm ({DRAGS})", each("waited_s", "{:.2f}")),
                (f"confirm s ({DRAGS})", each("confirm_s", "{:.2f}")),
                ("stretch % of each confirm", each("stretch_pct", "{:.1f}")),
                ("api.deform s", lambda r: number(r.get("deform_s"), "{:.2f}")),
                ("drag adds MB to peak", lambda r: f"{r['drag_peak_mb_added']:.0f}"),
                ("peak MB", lambda r: f"{r['peak_mb']:.0f}")], rows))


def files(rows, title="The bound file"):
    """The file figures of the rows that have them (rows of the files part name their faces)."""
    rows = [r for r in rows if "files" in r]  # rows of results written before the file figures: none
    if not rows:
        return ""
    faces = [("faces", lambda r: r["faces"])] if all("faces" in r for r in rows) else []
    # The files part's rows: the preview's size too (stored with the binding, rebuilt each drag
    # move; the large part's table has it already); rows measured before it was recorded: none.
    previews = ([("preview vertices", lambda r: f"{r['preview_vertices']:,}")]
                if faces and all("preview_vertices" in r for r in rows) else [])
    return (f"\n### {title}\n\nThe rigged mesh of each row saved and opened (bpy's open_mainfile) with its binding, "
            "then without it (plain: the rig and the record removed); after opening, the seconds until it is "
            "prepared (the skin bound again and the layout prepared on the background thread, polled every 50 ms) "
            "and the longest the main thread was held meanwhile.\n\n" + table(faces + [
                ("vertices", lambda r: f"{r['vertices']:,}")] + previews + [
                ("save s", lambda r: f"{r['files']['save_s']:.2f}"),
                (".blend MB (x plain)", lambda r: f"{r['files']['blend_mb']:.0f} ({r['files']['size_x']:.2f})"),
                ("plain MB", lambda r: f"{r['files']['plain_mb']:.0f}"),
                ("open s (x plain)", lambda r: f"{r['files']['open_s']:.2f} ({r['files']['open_x']:.2f})"),
                ("plain open s", lambda r: f"{r['files']['plain_open_s']:.2f}"),
                ("prepared after open s", lambda r: f"{r['files']['prepared_s']:.2f}"),
                ("main thread held max ms", lambda r: f"{r['files']['main_thread_max_ms']:.0f}")], rows))


def tables(figures):
    """The tables of every part in ``figures`` (dict: "table1", "side", "large", "files" -> rows)."""
    return ((table1(figures["table1"]) if figures.get("table1") else "") +
            "".join(side(row) for row in figures.get("side", [])) +
            (large(figures["large"]) + files(figures["large"]) if figures.get("large") else "") +
            (files(figures["files"], "The bound file: triangles and quads (goal <= 1.3x the plain file)")
             if figures.get("files") else ""))
