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
      description: "Frames to bake, e.g. 1-250, 1..250 or 1-10,20",
    },
    {
      key: "chunk_size", type: "int32", default: 10, propargs: { min: 1, max: 1000 },
      description: "Frames per task",
    },
    {
      key: "object", type: "string", default: "",
      eval: "C.active_object.name if C.active_object else ''",
      evalInfo: { showLinkButton: true, description: "The active object" },
      description: "The bound mesh (or its proxy or a handle); empty: the only bound mesh in the file",
    },
    {
      key: "output_folder", type: "string", subtype: "dir_path", required: true,
      eval: "str(Path(abspath('//'), 'skin_detach_bake', jobname))",
      description: "Folder of the baked files: an absolute path on the shared storage, or one that starts " +
        "with a two-way variable such as {render}",
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

// A job bakes at most this many frames (as the bake CLI) in at most this many tasks.
const MAX_FRAMES = 100000;
const MAX_TASKS = 10000;

/** The settings with every missing one at its declared default (the Manager's REST API does not
 * apply them), checked; throws a message naming the setting. */
function checkedSettings(given) {
  const settings = {};
  for (const spec of JOB_TYPE.settings) {
    const value = given[spec.key];
    settings[spec.key] = value === undefined || value === null ? spec.default : value;
  }
  for (const spec of JOB_TYPE.settings) {
    const value = settings[spec.key];
    const kind = { string: "string", int32: "number", float: "number", bool: "boolean" }[spec.type];
    if (value === undefined && spec.required) {
      throw "Skin Detach bake: " + spec.key + " is required (" + spec.description + ")";
    }
    if (value !== undefined && typeof value !== kind) {
      throw "Skin Detach bake: " + spec.key + " must be a " + spec.type + ", got " + JSON.stringify(value);
    }
  }
  return settings;
}

/** Throws unless ``text`` is a frame range Flamenco's chunker takes (1-250, 1..250, 1-10,20; no
 * negative frames, no steps) of at most MAX_FRAMES frames. */
function checkFrames(text) {
  let count = 0;
  for (const part of text.replace(/\s/g, "").split(",")) {
    const match = /^(\d{1,9})(?:(?:-|\.\.)(\d{1,9}))?$/.exec(part);
    if (!match) {
      throw "Skin Detach bake: frames must be a frame range like 1-250, 1..250 or 1-10,20 (Flamenco's chunks " +
        "take no negative frames and no steps), got " + JSON.stringify(text);
    }
    const first = Number(match[1]);
    const last = match[2] === undefined ? first : Number(match[2]);
    if (last < first) {
      throw "Skin Detach bake: frames must not run backwards, got " + JSON.stringify(part);
    }
    count += last - first + 1;
    if (count > MAX_FRAMES) {
      throw "Skin Detach bake: frames must be at most " + MAX_FRAMES + " frames, got " + JSON.stringify(text);
    }
  }
}

/** Absolute on some platform (/x, C:/x or a drive and backslash, two backslashes and a server) or
 * starting with a variable ({render}/x). */
function isAbsolute(folder) {
  return /^(\/|[A-Za-z]:[\\/]|\\\\|\{[A-Za-z0-9_]+\})/.test(folder);
}

/** ``text`` made safe for a file name: anything but letters, digits, dot, dash, underscore -> _. */
function safeName(text) {
  return String(text).replace(/[^A-Za-z0-9._-]+/g, "_");
}

function compileJob(job) {
  const settings = checkedSettings(job.settings);
  if (FORMATS.indexOf(settings.format) < 0) {
    throw "Skin Detach bake: the farm writes one file per frame (.obj or .ply) so that chunks can run apart; " +
      "format " + JSON.stringify(settings.format) + " cannot be split (bake shape keys, objects or a .blend " +
      "on one machine with scripts/bake.py)";
  }
  if (/\.blend$/i.test(settings.output_folder)) {
    throw "Skin Detach bake: output_folder must be a folder, got the .blend " + JSON.stringify(settings.output_folder) +
      " (a .blend output cannot be split across tasks)";
  }
  if (!isAbsolute(settings.output_folder)) {
    throw "Skin Detach bake: output_folder must be an absolute path on the shared storage (or start with a " +
      "two-way variable such as {render}), got " + JSON.stringify(settings.output_folder) +
      " (a relative folder would land in each Worker's working folder)";
  }
  if (!settings.blendfile) {
    throw "Skin Detach bake: no .blend to bake (the Flamenco add-on fills in blendfile on submission)";
  }
  const size = settings.chunk_size;
  if (!(Number.isInteger(size) && size >= 1)) {
    throw "Skin Detach bake: chunk_size must be a whole number of at least 1, got " + JSON.stringify(size);
  }
  checkFrames(settings.frames);
  const chunks = frameChunker(settings.frames, size);
  if (chunks.length > MAX_TASKS) {
    throw "Skin Detach bake: " + chunks.length + " tasks is more than " + MAX_TASKS + "; raise chunk_size " +
      "(Flamenco adds about 5 s a task)";
  }
  const stem = safeName(path.stem(settings.blendfile));
  const pattern = path.join(settings.output_folder, safeName(job.name) + "_" + stem + "_####" + settings.format);
  const head = ["--python-exit-code", "1", "--python-expr", BAKE_EXPR, "--"];
  const bakes = [];
  for (const chunk of chunks) {
    const task = author.Task("bake-" + chunk, "blender");
    // --name=value: a value starting with a dash (negative frames, an object named -scan) stays a value.
    const args = head.concat([
      "--frames=" + chunk,
      "--output=" + pattern,
      "--object=" + settings.object,
      "--modifiers=" + (settings.apply_modifiers ? "apply" : "ignore"),
      "--volume=" + (settings.preserve_volume ? "keep" : "free"),
      "--farm",
    ]);
    task.addCommand(author.Command("blender-render", {
      exe: "{blender}",
      exeArgs: "{blenderArgs}",
      argsBefore: [],
      blendfile: settings.blendfile,
      args: args,
    }, frameCount(chunk)));
    job.addTask(task);
    bakes.push(task);
  }
  // The last task: every frame made its file (or the job fails, naming the missing frames).
  const verify = author.Task("verify-files", "blender");
  verify.addCommand(author.Command("blender-render", {
    exe: "{blender}",
    exeArgs: "{blenderArgs}",
    argsBefore: [],
    blendfile: settings.blendfile,
    args: head.concat(["--frames=" + settings.frames, "--output=" + pattern, "--verify"]),
  }, 1));
  for (const task of bakes) {
    verify.addDependency(task);
  }
  job.addTask(verify);
}
