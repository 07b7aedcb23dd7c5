// node --test tests/farm: the skin-detach-bake Flamenco job type under the compiler stand-in.
"use strict";
const test = require("node:test");
const assert = require("node:assert/strict");
const nodePath = require("node:path");
const { loadJobType, frameChunker, parseRange } = require("./flamenco_stand_in.js");

const JOB = nodePath.join(__dirname, "..", "..", "farm", "flamenco", "skin_detach_bake.js");
const SETTINGS = { frames: "1-250", chunk_size: 10, object: "scan", output_folder: "/render/shot/bake", format: ".obj",
  apply_modifiers: false, preserve_volume: true, blendfile: "/render/shot/shot010.blend" };

/** The value of ``--name=value`` in ``args`` (undefined when absent). */
function option(args, name) {
  const found = args.find((a) => a.startsWith(name + "="));
  return found === undefined ? undefined : found.slice(name.length + 1);
}

test("the stand-in chunks as Flamenco does", () => {
  assert.deepEqual(frameChunker("1-30", 7), ["1-7", "8-14", "15-21", "22-28", "29,30"]);
  assert.deepEqual(frameChunker("21-25,40", 10), ["21-25,40"]);
  assert.deepEqual(frameChunker("1..4", 3), ["1-3", "4"]);
});

test("250 frames in chunks of 10 make 25 blender-render tasks of 10 steps and a last check", () => {
  const tasks = loadJobType(JOB).compileJob(SETTINGS, "s010");
  assert.equal(tasks.length, 26);
  const covered = [];
  for (const task of tasks.slice(0, 25)) {
    assert.equal(task.type, "blender");
    assert.equal(task.commands.length, 1);
    const command = task.commands[0];
    assert.equal(command.name, "blender-render");
    const p = command.parameters;
    assert.equal(p.exe, "{blender}");            // left for the Manager to expand per Worker
    assert.equal(p.exeArgs, "{blenderArgs}");
    assert.equal(p.blendfile, SETTINGS.blendfile);
    const frames = option(p.args, "--frames");
    assert.equal(command.totalStepCount, parseRange(frames).length);
    covered.push(...parseRange(frames));
    assert.equal(option(p.args, "--output"), "/render/shot/bake/s010_shot010_####.obj");
    assert.deepEqual(p.args.slice(0, 3), ["--python-exit-code", "1", "--python-expr"]);  // fail on any error
    assert.deepEqual(p.args.slice(p.args.indexOf("--object=scan")), ["--object=scan", "--modifiers=ignore",
      "--volume=keep", "--farm"]);
  }
  assert.deepEqual(covered, Array.from({ length: 250 }, (_, i) => i + 1));
  const last = tasks[25];
  assert.equal(last.name, "verify-files");
  assert.equal(last.dependencies.length, 25);
  const args = last.commands[0].parameters.args;
  assert.equal(option(args, "--frames"), "1-250");
  assert.ok(args.includes("--verify"));
});

test("outputs that cannot be split are rejected with a message", () => {
  const jobType = loadJobType(JOB);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, format: ".blend" }), /cannot be split/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, output_folder: "/render/baked.blend" }), /must be a folder/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, blendfile: "" }), /no \.blend to bake/);
});

test("a submission that leaves settings out gets their declared defaults", () => {
  const { frames, output_folder, blendfile } = SETTINGS;
  const tasks = loadJobType(JOB).compileJob({ frames, output_folder, blendfile }, "api");
  const args = tasks[0].commands[0].parameters.args;
  assert.equal(tasks.length, 26);                   // chunk_size 10
  assert.equal(option(args, "--volume"), "keep");  // preserve_volume true, not "free"
  assert.equal(option(args, "--modifiers"), "ignore");
  assert.equal(option(args, "--object"), "");
  assert.ok(option(args, "--output").endsWith(".obj"));
});

test("a relative or missing output folder is refused; absolute ones and two-way variables are taken", () => {
  const jobType = loadJobType(JOB);
  for (const folder of ["bake", "./bake", "", undefined]) {
    assert.throws(() => jobType.compileJob({ ...SETTINGS, output_folder: folder }), /output_folder/);
  }
  for (const folder of ["/render/bake", "C:\\render\\bake", "D:/bake", "\\\\server\\share\\bake", "{render}/bake"]) {
    assert.doesNotThrow(() => jobType.compileJob({ ...SETTINGS, output_folder: folder }));
  }
});

test("bad frames, too many tasks and bad types are refused naming the setting", () => {
  const jobType = loadJobType(JOB);
  for (const frames of ["", "a-b", "10-1", "1-5:2", "-3-2", "1-100001"]) {
    assert.throws(() => jobType.compileJob({ ...SETTINGS, frames }), /frames/, frames);
  }
  assert.throws(() => jobType.compileJob({ ...SETTINGS, frames: "1-100000", chunk_size: 1 }), /chunk_size/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, chunk_size: 2.5 }), /chunk_size/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, preserve_volume: "yes" }), /preserve_volume/);
});

test("a value starting with a dash stays a value and the job name cannot make folders", () => {
  const tasks = loadJobType(JOB).compileJob({ ...SETTINGS, object: "-scan" }, "shot 10/take:2");
  const args = tasks[0].commands[0].parameters.args;
  assert.ok(args.includes("--object=-scan"));
  assert.equal(option(args, "--output"), "/render/shot/bake/shot_10_take_2_shot010_####.obj");
});

test("the settings: scene range with a link button, chunk size, active object, format choices", () => {
  const settings = Object.fromEntries(loadJobType(JOB).JOB_TYPE.settings.map((s) => [s.key, s]));
  assert.equal(settings.frames.evalInfo.showLinkButton, true);
  assert.equal(settings.chunk_size.type, "int32");
  assert.ok(settings.object.eval.includes("C.active_object"));
  assert.deepEqual(settings.format.choices, [".obj", ".ply"]);
  assert.equal(settings.blendfile.required, true);
});
