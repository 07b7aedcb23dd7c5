"""Run the add-on's GUI tests in a real Blender window, as an artist uses it.

    python scripts/gui_test.py [--zip dist/...linux_x64.zip] [-k NAME] [--pictures docs]

Blender: the one named by ``BLENDER=`` (run on this machine, under its ``xvfb-run``), or Debian's
``blender`` package (sid: 5.2.x LTS on the system Python 3.14) in a root file system that
``debootstrap`` makes once in ``$SKIN_DETACH_CACHE`` (default ``~/.cache/skin-detach``, outside
the clone) and reuses while its marker file names the same packages. That needs root and network
to Debian's archive (about 3 minutes and 2 GB the first time).

Steps: install the extension zip with ``blender --command extension install-file -e`` into a
fresh user folder (this is the install check: it fails when Blender refuses the zip), then run
each GUI test (``tests/gui/test_*.py``, one generator per test) in its own Blender process, in a
1600x900 window under Xvfb with ``--enable-event-simulate``. Every step after a test's set-up is
an event (keys, mouse, panel buttons, F3, menus). A failing test leaves a screenshot of the window
in ``out/gui/``. Prints one line per test and ``N passed, N failed``; exits 1 on any failure.
A run of every test also fails when an operator of the add-on was never driven by an event in
any of them (the coverage line; the runner reads what the Info editor logged as run).
``--pictures DIR`` runs the picture takers (``tests/gui/pictures.py``) instead and writes the
docs' pictures of the real window into DIR.
"""

import argparse
import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: Debian suite and packages of the cached root file system (its marker holds this text).
SUITE = "sid"
PACKAGES = "blender python3-numpy python3-requests python3-cattr xvfb xauth libgl1-mesa-dri imagemagick"
MIRROR = "http://deb.debian.org/debian"
#: Where the project is seen inside the root file system.
INSIDE = "/mnt/skin-detach"
SCREEN = "1600x900x24"
#: Seconds a single GUI test may take (a test that hangs is killed and fails).
TEST_TIMEOUT_S = 240


class GuiSetupFailed(Exception):
    pass


def run_session(command, timeout=None, env=None):
    """``subprocess.run(command)`` in a session of its own: on a timeout the whole session (Blender
    and the X server xvfb-run started for it) is killed, and nothing else on the machine."""
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                          start_new_session=True) as process:
        try:
            stdout, stderr = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            os.killpg(process.pid, signal.SIGKILL)
            exc.stdout, exc.stderr = process.communicate()
            raise
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


def run(command, **kwargs):
    done = subprocess.run(command, capture_output=True, text=True, **kwargs)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise GuiSetupFailed(f"{' '.join(map(str, command))}: exit {done.returncode}\n{tail}")
    return done


class Chroot:
    """Debian's Blender in a cached root file system: made when missing, mounted while in use."""

    def __init__(self, cache):
        self.root = cache / f"blender-{SUITE}"
        self.marker = self.root / ".skin-detach-packages"
        self.mounted = []
        self.blender = "blender"

    def ensure(self):
        if self.marker.exists() and self.marker.read_text().strip() == PACKAGES:
            return
        if os.geteuid() != 0:
            raise GuiSetupFailed(f"{self.root}: expected a cached Debian root with Blender, got none; making one "
                                 f"needs root (debootstrap, chroot), or set BLENDER=/path/to/blender")
        print(f"gui: making Debian {SUITE} with Blender in {self.root} (once; about 3 minutes)", flush=True)
        if shutil.which("debootstrap") is None:
            run(["apt-get", "update", "-qq"])
            run(["apt-get", "install", "-y", "-qq", "debootstrap"], env=dict(os.environ, DEBIAN_FRONTEND="noninteractive"))
        partial = self.root.with_name(self.root.name + ".partial")
        self._unmount_all(partial)
        shutil.rmtree(partial, ignore_errors=True)
        shutil.rmtree(self.root, ignore_errors=True)
        run(["debootstrap", "--variant=minbase", SUITE, str(partial), MIRROR])
        self.mount(partial)
        try:
            self.shell("apt-get -o Acquire::Check-Valid-Until=false update -qq && DEBIAN_FRONTEND=noninteractive "
                       f"apt-get install -y -qq --no-install-recommends {PACKAGES}", root=partial)
        finally:
            self.unmount()
        (partial / self.marker.name).write_text(PACKAGES + "\n")
        partial.rename(self.root)

    def mount(self, root=None):
        root = root or self.root
        for kind, source, target in (("proc", "proc", "proc"), ("bind", "/dev", "dev"), ("bind", "/dev/pts", "dev/pts"),
                                     ("tmpfs", "tmpfs", "tmp"), ("bind", str(ROOT), INSIDE.lstrip("/"))):
            point = root / target
            point.mkdir(parents=True, exist_ok=True)
            if os.path.ismount(point):
                continue
            command = ["mount", "--bind", source, str(point)] if kind == "bind" else \
                ["mount", "-t", kind, source, str(point)]
            run(command)
            self.mounted.append(point)

    def unmount(self):
        for point in reversed(self.mounted):
            subprocess.run(["umount", "-l", str(point)], capture_output=True)
        self.mounted.clear()

    @staticmethod
    def _unmount_all(root):
        if root.exists():
            for target in ("mnt/skin-detach", "tmp", "dev/pts", "dev", "proc"):
                subprocess.run(["umount", "-l", str(root / target)], capture_output=True)

    def shell(self, script, root=None, env=None, timeout=None):
        exports = "".join(f"export {k}={v}; " for k, v in (env or {}).items())
        return run_session(["chroot", str(root or self.root), "bash", "-c", exports + script], timeout=timeout)

    def path(self, host_path):
        """Where a file of the project is seen inside."""
        return f"{INSIDE}/{pathlib.Path(host_path).resolve().relative_to(ROOT)}"


class Host:
    """A Blender named by BLENDER=, run on this machine."""

    def __init__(self, blender):
        self.blender = blender

    def ensure(self):
        if shutil.which("xvfb-run") is None:
            raise GuiSetupFailed("xvfb-run: expected on PATH to run BLENDER in a window, not found "
                                 "(apt-get install xvfb xauth)")

    def mount(self):
        pass

    def unmount(self):
        pass

    def shell(self, script, env=None, timeout=None):
        return run_session(["bash", "-c", script], timeout=timeout, env=dict(os.environ, **(env or {})))

    def path(self, host_path):
        return str(pathlib.Path(host_path).resolve())


def find_zip(given):
    if given:
        return pathlib.Path(given)
    found = sorted((ROOT / "dist").glob("skin_detach_addon-*-linux_x64.zip"))
    if not found:
        raise GuiSetupFailed("dist/: expected the linux-x64 zip of `make extension`, found none")
    return found[-1]


def tests(selection):
    """(module, test) names of every GUI test, or those whose name contains ``selection``."""
    sys.path.insert(0, str(ROOT / "tests" / "gui"))
    found = []
    for path in sorted((ROOT / "tests" / "gui").glob("test_*.py")):
        text = path.read_text()
        for line in text.splitlines():
            if line.startswith("def test_"):
                name = line[4:line.index("(")]
                if not selection or selection in f"{path.stem}::{name}":
                    found.append((path.stem, name))
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--zip", help="extension zip (default: dist/*linux_x64.zip)")
    parser.add_argument("-k", default="", help="run only tests whose module::name contains this")
    parser.add_argument("--pictures", help="take the docs' pictures into this folder instead of testing")
    parser.add_argument("--out", default=str(ROOT / "out" / "gui"))
    args = parser.parse_args()
    cache = pathlib.Path(os.environ.get("SKIN_DETACH_CACHE", pathlib.Path.home() / ".cache" / "skin-detach"))
    blender = os.environ.get("BLENDER")
    where = Host(blender) if blender else Chroot(cache)
    out = pathlib.Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    started = time.monotonic()
    try:
        zip_path = find_zip(args.zip)
        if ROOT not in zip_path.resolve().parents:  # seen inside the root file system only below the project
            zip_path = pathlib.Path(shutil.copy2(zip_path, out / zip_path.name))
        where.ensure()
        where.mount()
        user = "/tmp/skin-detach-user" if not blender else str(out / "user")
        env = {"BLENDER_USER_RESOURCES": user}
        installed = where.shell(f"rm -rf {user} && {where.blender} --command extension install-file -r user_default -e "
                                f"{where.path(zip_path)}", env=env, timeout=300)
        version = where.shell(f"{where.blender} --version", env=env, timeout=60).stdout.splitlines()[:1]
        print(f"gui: {version[0] if version else 'blender'}; install-file {zip_path.name}: exit {installed.returncode}",
              flush=True)
        if installed.returncode != 0:
            print(installed.stdout + installed.stderr)
            print("0 passed, 1 failed")
            return 1
        todo = [("pictures", "take_pictures"), ("pictures", "take_parts_picture")] if args.pictures else tests(args.k)
        passed = failed = 0
        operators, driven = set(), set()
        for module, name in todo:
            result = out / f"{module}.{name}.json"
            extra = f" --pictures {where.path(pathlib.Path(args.pictures))}" if args.pictures else ""
            command = (f"xvfb-run -a -s '-screen 0 {SCREEN}' {where.blender} --enable-event-simulate {os.environ.get('GUI_BLENDER_ARGS', '')} --python "
                       f"{where.path(ROOT / 'tests' / 'gui' / 'runner.py')} -- --test {module}::{name} "
                       f"--result {where.path(result)}{extra}")
            begun = time.monotonic()
            try:
                done = where.shell(command, env=env, timeout=TEST_TIMEOUT_S)
                log = done.stdout + done.stderr
            except subprocess.TimeoutExpired as exc:
                log = f"timed out after {TEST_TIMEOUT_S} s (killed)\n{exc.stdout or ''}{exc.stderr or ''}"
            (out / f"{module}.{name}.log").write_text(log if isinstance(log, str) else log.decode(errors="replace"))
            outcome = json.loads(result.read_text()) if result.exists() else {"passed": False, "message":
                                                                               "no result (Blender crashed or hung): "
                                                                               + log.strip()[-800:]}
            seconds = time.monotonic() - begun
            operators.update(outcome.get("operators", ()))
            driven.update(outcome.get("driven", ()))
            if outcome["passed"]:
                passed += 1
                print(f"PASSED {module}::{name} ({seconds:.0f} s)", flush=True)
            else:
                failed += 1
                print(f"FAILED {module}::{name} ({seconds:.0f} s): {outcome['message']}", flush=True)
                if outcome.get("screenshot"):
                    print(f"       screenshot: {result.with_suffix('.png')}", flush=True)
        if operators and not args.pictures:
            never = sorted(operators - driven)
            if not never:
                print(f"PASSED coverage: all {len(operators)} operators of the add-on driven by events", flush=True)
            elif args.k:  # a partial run: says what it drove, fails nothing
                print(f"coverage of this run: {len(operators) - len(never)} of {len(operators)} operators driven by "
                      f"events; not: {', '.join(never)}", flush=True)
            else:
                failed += 1
                print(f"FAILED coverage: never driven by an event in any GUI test: {', '.join(never)}", flush=True)
        print(f"gui: {time.monotonic() - started:.0f} s in all")
        print(f"{passed} passed, {failed} failed")
        return 1 if failed or not todo else 0
    except GuiSetupFailed as exc:
        print(f"gui_test: error: {exc}", file=sys.stderr)
        return 1
    finally:
        where.unmount()


if __name__ == "__main__":
    sys.exit(main())
