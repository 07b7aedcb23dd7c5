// A small stand-in for the globals Flamenco 3's job compiler gives a job type (written from the
// project's notes on Flamenco, not from its code): author.Task / author.Command, frameChunker,
// frameCount, path, print; and a job object with settings and addTask. Loads a job type file.
"use strict";
const fs = require("node:fs");
const nodePath = require("node:path");
const vm = require("node:vm");

/** Frames of "1-30", "1..30", "1-10,20" (in order, no repeats). */
function parseRange(range) {
  const frames = [];
  const seen = new Set();
  for (const part of String(range).replace(/\s/g, "").split(",")) {
    const match = /^(\d+)(?:(?:-|\.\.)(\d+))?$/.exec(part);
    if (!match) throw "invalid frame range " + JSON.stringify(range);
    const first = Number(match[1]);
    const last = match[2] === undefined ? first : Number(match[2]);
    for (let f = first; f <= last; f++) if (!seen.has(f)) { seen.add(f); frames.push(f); }
  }
  return frames;
}

/** A chunk's frames as Flamenco writes them: runs of 3+ as a-b, shorter runs frame by frame. */
function formatChunk(frames) {
  const parts = [];
  let start = 0;
  for (let i = 1; i <= frames.length; i++) {
    if (i === frames.length || frames[i] !== frames[i - 1] + 1) {
      const run = frames.slice(start, i);
      if (run.length >= 3) parts.push(run[0] + "-" + run[run.length - 1]);
      else parts.push(...run.map(String));
      start = i;
    }
  }
  return parts.join(",");
}

function frameChunker(range, chunkSize) {
  const frames = parseRange(range);
  const out = [];
  for (let i = 0; i < frames.length; i += chunkSize) out.push(formatChunk(frames.slice(i, i + chunkSize)));
  return out;
}

const author = {
  Task(name, taskType) {
    return { name, type: taskType, commands: [], dependencies: [],
      addCommand(command) { this.commands.push(command); },
      addDependency(task) { this.dependencies.push(task.name); } };
  },
  Command(name, parameters, totalStepCount) { return { name, parameters, totalStepCount }; },
};

const path = {
  basename: (p) => nodePath.posix.basename(p),
  dirname: (p) => nodePath.posix.dirname(p),
  join: (...parts) => nodePath.posix.join(...parts),
  stem: (p) => nodePath.posix.basename(p, nodePath.posix.extname(p)),
};

/** { JOB_TYPE, compileJob(settings, name) -> tasks } of the job type file at ``file``. */
function loadJobType(file) {
  const context = vm.createContext({ author, frameChunker, frameCount: (r) => parseRange(r).length, path,
    print: () => {}, process: { cwd: () => "/", platform: "linux" } });
  vm.runInContext(fs.readFileSync(file, "utf8"), context, { filename: file });
  const jobType = vm.runInContext("JOB_TYPE", context);
  const compile = vm.runInContext("compileJob", context);
  // Plain copies: arrays made inside the VM context have that context's prototypes.
  const plain = (value) => JSON.parse(JSON.stringify(value));
  return {
    JOB_TYPE: plain(jobType),
    compileJob(settings, name = "bake") {
      const job = { name, settings, created: new Date(0), tasks: [], addTask(task) { this.tasks.push(task); } };
      compile(job);
      return plain(job.tasks);
    },
  };
}

module.exports = { loadJobType, frameChunker, parseRange };

// node flamenco_stand_in.js JOB_TYPE_FILE SETTINGS_JSON [JOB_NAME]: the compiled tasks as JSON.
if (require.main === module) {
  const [file, settings, name] = process.argv.slice(2);
  process.stdout.write(JSON.stringify(loadJobType(file).compileJob(JSON.parse(settings), name || "bake")));
}
