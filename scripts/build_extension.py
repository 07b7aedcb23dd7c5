"""Build the installable extension: one zip per platform, each carrying the scipy and
fast-simplification wheels Blender needs (numpy ships with Blender).

    python scripts/build_extension.py [--platforms linux-x64,windows-x64,...] [--out dist]

For every platform it downloads (pip, binary wheels only, no dependencies) scipy and
fast-simplification for CPython 3.11 (Blender 4.2 to 5.0) and 3.13 (Blender 5.1 and later), and
on Linux for 3.14 too (Linux distributions' own Blender packages run the system's Python 3.14;
no official Blender runs it, and fast-simplification has no 3.14 wheel for Intel macOS), stages
``skin_detach_addon/`` with ``blender_manifest.toml`` plus the wheel list, builds with Blender's
own extension tool (``blender_ext.py build --split-platforms``, shipped in the bpy wheel) and
runs its ``validate`` on every zip. It fails, naming what is missing, if a platform has no
wheel for a package and Python version, or a built zip lacks one.

The zips carry slimmed copies of the scipy wheels under the same file names (the manifest's
wheel list names them as pip downloaded them): without scipy's own test suites (every folder
named ``tests`` inside the ``scipy`` package, 4.4 MiB of each 27-35 MiB wheel, never imported by
a running add-on; the linux-x64 zip is 88 MiB instead of 102), each ``.dist-info/RECORD``
rewritten to list exactly the files kept with their sha256 and sizes, so each stays a valid
wheel. The downloads in the wheel cache are left untouched; the copies go into the staging folder.
"""

import argparse
import base64
import csv
import hashlib
import importlib.util
import io
import os
import pathlib
import re
import shutil
import subprocess
import sys
import zipfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
PACKAGES = {"scipy": "1.17.1", "fast-simplification": "0.2.0"}
PYTHONS = ("3.11", "3.13")
#: Python versions only Linux builds carry wheels for (a distribution's Blender on its own Python).
LINUX_PYTHONS = ("3.14",)
#: Blender platform -> pip platform tags, best first. macOS arm64 takes scipy's macosx_12_0 wheel
#: only (its macosx_14_0 wheel needs a newer macOS than Blender 4.2 does).
PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "linux-arm64": ["manylinux_2_28_aarch64", "manylinux_2_27_aarch64", "manylinux_2_17_aarch64",
                    "manylinux2014_aarch64"],
    "windows-x64": ["win_amd64"],
    "macos-x64": ["macosx_10_14_x86_64", "macosx_10_13_x86_64", "macosx_10_9_x86_64"],
    "macos-arm64": ["macosx_12_0_arm64", "macosx_11_0_arm64"],
}


#: Entries of a wheel the zips leave out, by package: scipy's test suites (folders named ``tests``
#: anywhere inside the scipy package; nothing outside them imports them).
LEFT_OUT = {"scipy": re.compile(r"scipy/(?:.+/)?tests/")}


class BuildFailed(Exception):
    pass


def pythons(platform):
    """The CPython versions whose wheels the zip of ``platform`` carries."""
    return PYTHONS + (LINUX_PYTHONS if platform.startswith("linux-") else ())


def blender_ext():
    """Path of Blender's extension command-line tool inside the installed bpy wheel, or the one
    ``$BLENDER_EXT`` names (a Blender installation's ``scripts/addons_core/bl_pkg/cli/blender_ext.py``)."""
    given = os.environ.get("BLENDER_EXT")
    if given:
        if not pathlib.Path(given).is_file():
            raise BuildFailed(f"BLENDER_EXT: expected the path of blender_ext.py, got {given!r} (no such file)")
        return pathlib.Path(given)
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildFailed("bpy: expected the bpy module installed (it ships blender_ext.py), it is not")
    found = sorted(pathlib.Path(spec.submodule_search_locations[0]).glob(
        "*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise BuildFailed("bpy: expected scripts/addons_core/bl_pkg/cli/blender_ext.py in the bpy wheel, not found")
    return found[-1]


def wheel_name(package):
    return package.replace("-", "_")


def cached(cache, package, python, platform):
    """Wheels of ``package`` for CPython ``python`` and ``platform`` already in ``cache``."""
    abi = "cp" + python.replace(".", "")
    pattern = f"{wheel_name(package)}-{PACKAGES[package]}-{abi}-{abi}-*.whl"
    return sorted(p for p in cache.glob(pattern) if any(f"{tag}." in p.name for tag in PLATFORMS[platform]))


def download(platform, python, cache):
    """The wheels (paths in ``cache``) of every package for one platform and Python version."""
    abi = "cp" + python.replace(".", "")
    wheels = []
    for package, version in PACKAGES.items():
        if not cached(cache, package, python, platform):
            command = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
                       "--python-version", python, "--implementation", "cp", "--abi", abi, "--dest", str(cache)]
            for tag in PLATFORMS[platform]:
                command += ["--platform", tag]
            run = subprocess.run(command + [f"{package}=={version}"], capture_output=True, text=True)
            if run.returncode != 0:
                last = run.stderr.strip().splitlines()[-1] if run.stderr.strip() else "no message"
                raise BuildFailed(f"{platform}: expected a {package} {version} wheel for CPython {python}, "
                                  f"pip found none: {last}")
        found = cached(cache, package, python, platform)
        if not found:
            raise BuildFailed(f"{platform}: expected a {package} {version} wheel for CPython {python} in {cache}, "
                              f"pip downloaded none with tags {', '.join(PLATFORMS[platform])}")
        wheels.append(found[0])
    return wheels


def record_hash(data):
    """A RECORD hash of ``data`` (bytes), as the wheel spec writes it: ``sha256=`` and the
    urlsafe base64 digest without padding."""
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def slim_wheel(source, target, left_out):
    """Write ``target``, a copy of the wheel ``source`` without the entries whose names match
    ``left_out`` (a compiled regex), its ``*.dist-info/RECORD`` (written last) listing exactly the
    files kept with their sha256 and sizes (RECORD itself with neither). Entries keep their order,
    dates, permissions and compression. Fails if a kept file's content disagrees with the source's
    RECORD. Returns the number of entries left out."""
    with zipfile.ZipFile(source) as wheel:
        entries = wheel.infolist()
        records = [e for e in entries if re.fullmatch(r"[^/]+\.dist-info/RECORD", e.filename)]
        if len(records) != 1:
            raise BuildFailed(f"{source.name}: expected one *.dist-info/RECORD, got {[e.filename for e in records]}")
        record = records[0]
        listed = {row[0]: row for row in csv.reader(io.StringIO(wheel.read(record).decode("utf-8"))) if row}
        kept = [e for e in entries if not left_out.match(e.filename)]
        rows = []
        with zipfile.ZipFile(target, "w") as slim:
            for entry in kept:
                if entry is record:
                    continue
                data = wheel.read(entry)
                if not entry.is_dir():
                    row = [entry.filename, record_hash(data), str(len(data))]
                    if listed.get(entry.filename) != row:
                        raise BuildFailed(f"{source.name}: expected {entry.filename} as its RECORD lists it, "
                                          f"{listed.get(entry.filename)}, got {row}")
                    rows.append(row)
                slim.writestr(copy_info(entry), data)
            rows.append([record.filename, "", ""])
            text = io.StringIO()
            csv.writer(text, lineterminator="\n").writerows(rows)
            slim.writestr(copy_info(record), text.getvalue().encode("utf-8"))
    return len(entries) - len(kept)


def copy_info(entry):
    """A new ZipInfo with the name, date, permissions and compression of ``entry``."""
    info = zipfile.ZipInfo(entry.filename, entry.date_time)
    info.compress_type = entry.compress_type
    info.create_system = entry.create_system
    info.external_attr = entry.external_attr
    return info


def stage(platforms, wheels, folder):
    """Copy the add-on and the manifest (plus ``platforms`` and ``wheels``) into ``folder``, each
    wheel of a package in LEFT_OUT slimmed (same file name)."""
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(ROOT / "skin_detach_addon", folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (folder / "wheels").mkdir()
    for wheel in wheels:
        left_out = LEFT_OUT.get(wheel.name.split("-", 1)[0])
        if left_out is None:
            shutil.copy2(wheel, folder / "wheels" / wheel.name)
        else:
            slim = folder / "wheels" / wheel.name
            count = slim_wheel(wheel, slim, left_out)
            print(f"{wheel.name}: {count} test entries left out, {wheel.stat().st_size / 2**20:.1f} -> "
                  f"{slim.stat().st_size / 2**20:.1f} MiB", flush=True)
    manifest = (ROOT / "blender_manifest.toml").read_text()
    listed = ",\n".join(f'  "./wheels/{w.name}"' for w in sorted(wheels))
    quoted = ", ".join(f'"{p}"' for p in platforms)
    top_keys = f"platforms = [{quoted}]\nwheels = [\n{listed},\n]\n\n"
    table = manifest.find("\n[")  # top-level keys must come before the first [table]
    manifest = manifest + "\n" + top_keys if table < 0 else manifest[:table + 1] + top_keys + manifest[table + 1:]
    (folder / "blender_manifest.toml").write_text(manifest)


def build(platforms, out, cache):
    """Build and validate one zip per platform in ``out``; returns {platform: zip path}."""
    tool = blender_ext()
    cache.mkdir(parents=True, exist_ok=True)
    needed = {platform: [] for platform in platforms}
    for platform in platforms:
        for python in pythons(platform):
            needed[platform] += download(platform, python, cache)
            print(f"{platform} cp{python.replace('.', '')}: " + ", ".join(w.name for w in needed[platform][-2:]),
                  flush=True)
    staging = out / "staging"
    stage(platforms, sorted({w for ws in needed.values() for w in ws}), staging)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("skin_detach_addon-*.zip"):
        old.unlink()
    command = [sys.executable, str(tool), "build", "--source-dir", str(staging), "--output-dir", str(out),
               "--split-platforms"]
    run = subprocess.run(command, capture_output=True, text=True)
    if run.returncode != 0:
        raise BuildFailed(f"blender_ext build: {(run.stdout + run.stderr).strip()}")
    zips = {}
    for platform in platforms:
        found = list(out.glob(f"skin_detach_addon-*-{platform.replace('-', '_')}.zip"))
        if len(found) != 1:
            raise BuildFailed(f"{platform}: expected one zip in {out}, got {[z.name for z in found]}")
        check_zip(found[0], needed[platform])
        run = subprocess.run([sys.executable, str(tool), "validate", str(found[0])], capture_output=True, text=True)
        if run.returncode != 0:
            raise BuildFailed(f"blender_ext validate {found[0].name}: {(run.stdout + run.stderr).strip()}")
        zips[platform] = found[0]
    shutil.rmtree(staging)
    return zips


def check_zip(path, wheels):
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
    missing = [w.name for w in wheels if f"wheels/{w.name}" not in names]
    if missing:
        raise BuildFailed(f"{path.name}: expected the wheels {', '.join(missing)} inside, they are missing")
    for required in ("__init__.py", "blender_manifest.toml", "api.py", "core/proxy_solve/dual_laplacian.py"):
        if required not in names:
            raise BuildFailed(f"{path.name}: expected {required} inside, it is missing")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--platforms", default=",".join(PLATFORMS),
                        help=f"comma-separated, from {', '.join(PLATFORMS)} (default: all)")
    parser.add_argument("--out", default=str(ROOT / "dist"))
    parser.add_argument("--wheels", default=str(ROOT / "build" / "wheels"), help="download cache for the wheels")
    args = parser.parse_args()
    platforms = [p.strip() for p in args.platforms.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in PLATFORMS]
    if unknown or not platforms:
        parser.error(f"--platforms: expected names from {', '.join(PLATFORMS)}, got {args.platforms!r}")
    try:
        zips = build(platforms, pathlib.Path(args.out), pathlib.Path(args.wheels))
    except BuildFailed as exc:
        print(f"build_extension: error: {exc}", file=sys.stderr)
        sys.exit(1)
    for platform, path in zips.items():
        print(f"{platform}: {path} ({path.stat().st_size / 2**20:.1f} MiB), validated")


if __name__ == "__main__":
    main()
