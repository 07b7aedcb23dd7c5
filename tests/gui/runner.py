"""Runs one GUI test inside a real Blender window (started by scripts/gui_test.py):

    blender --enable-event-simulate --python tests/gui/runner.py -- --test MODULE::NAME --result FILE.json

The test is a generator function of ``tests/gui/MODULE.py`` taking a :class:`gui.Ui`; it yields
to let Blender's event loop run (a number: seconds to wait) and raises AssertionError on a
failure. The runner drives it from a timer, writes ``{"passed", "message", "screenshot",
"operators", "driven"}`` to the result file (a screenshot of the whole window next to it on a
failure; the add-on's operators and those of them the test's events ran, see
:func:`logged_operators`) and quits Blender."""

import collections
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


#: bl_idname -> finished ``bpy.ops.skin_detach`` calls made by script (a test's set-up): Blender
#: logs them in the Info editor as it logs those run by events.
SCRIPTED = collections.Counter()


class _CountedOperator:
    """``bpy.ops.<module>.<name>``, counting its finished calls into :data:`SCRIPTED`."""

    def __init__(self, function, idname):
        self._function, self._idname = function, idname

    def __call__(self, *args, **kwargs):
        result = self._function(*args, **kwargs)
        if 'FINISHED' in result:
            SCRIPTED[self._idname] += 1
        return result

    def __getattr__(self, name):
        return getattr(self._function, name)


def count_scripted_calls():
    """Make every script's ``bpy.ops.skin_detach.*`` call counted (see :data:`SCRIPTED`)."""
    import bpy.ops
    original = getattr(bpy.ops, "_bpy_ops_submodule__getattr__", None)
    if original is None:  # another Blender's bpy.ops: nothing counts as driven (the coverage fails, saying so)
        print("runner: bpy.ops._bpy_ops_submodule__getattr__ not found: script calls cannot be told from "
              "events, no operator counts as driven", file=sys.stderr)
        SCRIPTED["*"] = 1
        return

    def counted(module, name):
        function = original(module, name)
        return _CountedOperator(function, f"{module}.{name}") if module == "skin_detach" else function

    bpy.ops._bpy_ops_submodule__getattr__ = counted


def logged_operators():
    """(the bl_idnames of the add-on's operators, those of them driven by events in this test).
    Blender logs an operator run in the window (a key, a button, a menu, F3; modal ones when they
    finish; one that raised as well, not one that reported an error and cancelled) as its Python
    line in the Info editor, and a script's ``bpy.ops`` call too: an
    operator counts as driven when it was logged more often than a script called it. Read by
    script at the end: the test's events are over."""
    try:
        package = gui.addon()
    except AssertionError:
        return [], []
    known = sorted(cls.bl_idname for cls in package.ui.CLASSES if issubclass(cls, bpy.types.Operator))
    window = bpy.context.window_manager.windows[0]
    areas = [a for a in window.screen.areas if a.type == 'INFO']
    if not areas:
        return known, []
    region = next(r for r in areas[0].regions if r.type == 'WINDOW')
    wm = bpy.context.window_manager
    wm.clipboard = ""
    with bpy.context.temp_override(window=window, area=areas[0], region=region):
        bpy.ops.info.select_all(action='SELECT')
        bpy.ops.info.report_copy()
    if SCRIPTED["*"]:
        return known, []
    lines = wm.clipboard.splitlines()
    logged = collections.Counter(idname for line in lines for idname in known if line.startswith(f"bpy.ops.{idname}("))
    return known, sorted(idname for idname in known if logged[idname] > SCRIPTED[idname])


def finish(passed, message):
    outcome = {"passed": passed, "message": message}
    try:
        outcome["operators"], outcome["driven"] = logged_operators()
    except Exception as exc:  # noqa: BLE001 - a test's result is written whatever happened here
        outcome["operators"], outcome["driven"] = [], []
        print(f"runner: the Info editor's log could not be read: {exc}", file=sys.stderr)
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
    count_scripted_calls()
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
