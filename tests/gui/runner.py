"""Runs one GUI test inside a real Blender window (started by scripts/gui_test.py):

    blender --enable-event-simulate --python tests/gui/runner.py -- --test MODULE::NAME --result FILE.json

The test is a generator function of ``tests/gui/MODULE.py`` taking a :class:`gui.Ui`; it yields
to let Blender's event loop run (a number: seconds to wait) and raises AssertionError on a
failure. The runner drives it from a timer, writes ``{"passed", "message", "screenshot"}`` to the
result file (a screenshot of the whole window next to it on a failure) and quits Blender."""

import json
import os
import pathlib
import subprocess
import sys
import time
import traceback

import bpy

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import gui  # noqa: E402  (tests/gui/gui.py, after the path is set)

#: Seconds one test may run inside Blender before it counts as hung.
DEADLINE_S = 200


def _arguments():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    out = {}
    for flag, value in zip(argv[::2], argv[1::2]):
        out[flag.lstrip("-")] = value
    return out


ARGS = _arguments()
RESULT = pathlib.Path(ARGS["result"])
MODULE, NAME = ARGS["test"].split("::")


def screenshot(path):
    """The whole X screen as a PNG (Blender's own screenshot is black under Xvfb); True if made."""
    try:
        subprocess.run(["import", "-window", "root", str(path)], check=True, capture_output=True, timeout=30)
        return True
    except (OSError, subprocess.SubprocessError):
        return False


def finish(passed, message):
    outcome = {"passed": passed, "message": message}
    if not passed:
        shot = RESULT.with_suffix(".png")
        if screenshot(shot):
            outcome["screenshot"] = str(shot)
    RESULT.write_text(json.dumps(outcome, indent=1))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def start():
    import importlib
    ui = gui.Ui(pictures=ARGS.get("pictures"))
    steps = getattr(importlib.import_module(MODULE), NAME)(ui)
    begun = time.monotonic()

    def tick():
        if time.monotonic() - begun > DEADLINE_S:
            finish(False, f"still running after {DEADLINE_S} s")
        try:
            delay = next(steps)
        except StopIteration:
            finish(True, "")
        except BaseException as exc:  # noqa: BLE001 - every failure is reported with its traceback
            lines = traceback.format_exception(exc)
            print("".join(lines), file=sys.stderr)
            finish(False, f"{type(exc).__name__}: {exc}".strip().replace("\n", " | ")[:2000])
        return gui.STEP_S if delay is None else float(delay)

    # Persistent: a test may open a file and go on in it.
    bpy.app.timers.register(tick, first_interval=1.0, persistent=True)


start()
