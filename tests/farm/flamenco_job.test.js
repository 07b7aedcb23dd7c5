// node --test tests/farm: the skin-detach-bake Flamenco job type under the compiler stand-in.
"use strict";
const test = require("node:test");
const assert = require("node:assert/strict");
const nodePath = require("node:path");
const { loadJobType, frameChunker, parseRange } = require("./flamenco_stand_in.js");

const JOB = nodePath.join(__dirname, "..", "..", "farm", "flamenco", "skin_detach_bake.js");
const SETTINGS = { frames: "1-250", chunk_size: 10, object: "scan", output_folder: "/render/shot/bake", format: ".obj",
  apply_modifiers: false, preserve_volume: true, blendfile: "/render/shot/shot010.blend" };

test("the stand-in chunks as Flamenco does", () => {
  assert.deepEqual(frameChunker("1-30", 7), ["1-7", "8-14", "15-21", "22-28", "29,30"]);
  assert.deepEqual(frameChunker("21-25,40", 10), ["21-25,40"]);
  assert.deepEqual(frameChunker("1..4", 3), ["1-3", "4"]);
});

test("250 frames in chunks of 10 make 25 blender-render tasks of 10 steps", () => {
  const tasks = loadJobType(JOB).compileJob(SETTINGS, "s010");
  assert.equal(tasks.length, 25);
  const covered = [];
  for (const task of tasks) {
    assert.equal(task.type, "blender");
    assert.equal(task.commands.length, 1);
    const command = task.commands[0];
    assert.equal(command.name, "blender-render");
    const p = command.parameters;
    assert.equal(p.exe, "{blender}");            // left for the Manager to expand per Worker
    assert.equal(p.exeArgs, "{blenderArgs}");
    assert.equal(p.blendfile, SETTINGS.blendfile);
    const frames = p.args[p.args.indexOf("--frames") + 1];
    assert.equal(command.totalStepCount, parseRange(frames).length);
    covered.push(...parseRange(frames));
    assert.equal(p.args[p.args.indexOf("--output") + 1], "/render/shot/bake/s010_shot010_####.obj");
    assert.deepEqual(p.args.slice(0, 3), ["--python-exit-code", "1", "--python-expr"]);  // fail on any error
    assert.deepEqual(p.args.slice(p.args.indexOf("--object")), ["--object", "scan", "--modifiers", "ignore",
      "--volume", "keep"]);
  }
  assert.deepEqual(covered, Array.from({ length: 250 }, (_, i) => i + 1));
});

test("outputs that cannot be split are rejected with a message", () => {
  const jobType = loadJobType(JOB);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, format: ".blend" }), /cannot be split/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, output_folder: "/render/baked.blend" }), /must be a folder/);
  assert.throws(() => jobType.compileJob({ ...SETTINGS, blendfile: "" }), /no \.blend to bake/);
});

test("the settings: scene range with a link button, chunk size, active object, format choices", () => {
  const settings = Object.fromEntries(loadJobType(JOB).JOB_TYPE.settings.map((s) => [s.key, s]));
  assert.equal(settings.frames.evalInfo.showLinkButton, true);
  assert.equal(settings.chunk_size.type, "int32");
  assert.ok(settings.object.eval.includes("C.active_object"));
  assert.deepEqual(settings.format.choices, [".obj", ".ply"]);
  assert.equal(settings.blendfile.required, true);
});
