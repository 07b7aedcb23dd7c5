// Skin Detach bake: a Flamenco 3 job type (put this file in the folder `scripts/` next to the
// flamenco-manager executable; the file name makes the job type `skin-detach-bake`).
//
// One task per chunk of frames; each runs the add-on's own bake CLI in Blender on a Worker that
// has the Skin Detach extension installed and enabled, from any extension repository (with its
// bundled scipy and fast-simplification): no checkout of the repository is needed. A task fails
// (non-zero exit) when the extension is missing or the bake fails for any reason:
// `--python-exit-code 1` makes Blender exit 1 after an uncaught Python error, where it exits 0.
// Frames go to one .obj or .ply file each, named from the job and the .blend; a frame gives the same
// bytes whichever chunk or Worker bakes it, and a killed task leaves only complete files (each
// file is written under a hidden partial name and renamed). The Manager expands {blender} and
// {blenderArgs} per Worker (variables in flamenco-manager.yaml).

// The same text as skin_detach_addon/bake_cli.py FARM_EXPR (a test compares them).
const BAKE_EXPR = "import importlib, sys, bpy; found = sorted(a.module for a in bpy.context.preferences.addons if a.module.rsplit('.', 1)[-1] == 'skin_detach_addon'); found or sys.exit('bake: error: the Skin Detach extension is not enabled in this Blender ' + bpy.app.version_string + '; install it on every Worker that takes bake tasks'); importlib.import_module(found[0] + '.bake_cli').main()";
const FORMATS = [".obj", ".ply"];

const JOB_TYPE = {
  label: "Skin Detach Bake",
  description: "Bake a Skin Detach rig's deformed mesh to one OBJ or PLY file per frame",
  settings: [
    {
      key: "frames", type: "string", required: true,
      eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
      evalInfo: { showLinkButton: true, description: "Scene frame range" },
      description: "Frames to bake, e.g. 1-250 or 1-10,20",
    },
    {
      key: "chunk_size", type: "int32", default: 10, propargs: { min: 1, max: 1000 },
      description: "Frames per task",
    },
    {
      key: "object", type: "string",
      eval: "C.active_object.name if C.active_object else ''",
      evalInfo: { showLinkButton: true, description: "The active object" },
      description: "The bound mesh (or its proxy or a handle); empty: the only bound mesh in the file",
    },
    {
      key: "output_folder", type: "string", subtype: "dir_path", required: true,
      eval: "str(Path(abspath('//'), 'skin_detach_bake', jobname))",
      description: "Folder of the baked files",
    },
    {
      key: "format", type: "string", required: true, default: ".obj", choices: FORMATS,
      description: "One file per frame: .obj (keeps the vertex order) or .ply",
    },
    { key: "apply_modifiers", type: "bool", default: false, description: "Export with the object's modifiers applied" },
    { key: "preserve_volume", type: "bool", default: true, description: "Keep the proxy's enclosed volume" },
    // Filled in by the Flamenco add-on with the path of the submitted .blend.
    { key: "blendfile", type: "string", required: true, visible: "web", description: "The .blend to bake" },
  ],
};

function compileJob(job) {
  const settings = job.settings;
  if (FORMATS.indexOf(settings.format) < 0) {
    throw "Skin Detach bake: the farm writes one file per frame (.obj or .ply) so that chunks can run apart; " +
      "format " + JSON.stringify(settings.format) + " cannot be split (bake shape keys, objects or a .blend " +
      "on one machine with scripts/bake.py)";
  }
  if (/\.blend$/i.test(settings.output_folder || "")) {
    throw "Skin Detach bake: output_folder must be a folder, got the .blend " + JSON.stringify(settings.output_folder) +
      " (a .blend output cannot be split across tasks)";
  }
  if (!settings.blendfile) {
    throw "Skin Detach bake: no .blend to bake (the Flamenco add-on fills in blendfile on submission)";
  }
  const size = settings.chunk_size;
  if (!(size >= 1)) {
    throw "Skin Detach bake: chunk_size must be at least 1, got " + size;
  }
  const stem = path.stem(settings.blendfile);
  const pattern = path.join(settings.output_folder, job.name + "_" + stem + "_####" + settings.format);
  for (const chunk of frameChunker(settings.frames, size)) {
    const task = author.Task("bake-" + chunk, "blender");
    const args = [
      "--python-exit-code", "1", "--python-expr", BAKE_EXPR, "--",
      "--frames", chunk,
      "--output", pattern,
      "--object", settings.object || "",
      "--modifiers", settings.apply_modifiers ? "apply" : "ignore",
      "--volume", settings.preserve_volume ? "keep" : "free",
    ];
    task.addCommand(author.Command("blender-render", {
      exe: "{blender}",
      exeArgs: "{blenderArgs}",
      argsBefore: [],
      blendfile: settings.blendfile,
      args: args,
    }, frameCount(chunk)));
    job.addTask(task);
  }
}
