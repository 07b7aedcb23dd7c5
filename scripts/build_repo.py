"""Build a static extension repository a studio hosts for its artists' Blender (4.2 and later).

    python scripts/build_repo.py [--platforms linux-x64,...] [--out dist/repo] [--html]

Builds every platform's zip with scripts/build_extension.py into ``--out`` and runs Blender's own
extension tool (``blender_ext.py server-generate``, shipped in the bpy wheel) on that folder to
write ``index.json`` (and ``index.html`` with ``--html``). Artists add the index's URL as a Remote
Repository (``file:///...`` on a share, or any static web server); see docs/studio.md.

Publishing a new version into the same folder: the zips of the version being built are replaced,
the zips of older versions of the add-on are moved to ``archive/`` in the folder (kept, not listed:
Blender installs the first listing entry of an id that fits the machine, whatever its version, so
the index lists one version only: the newest), zips of other extensions are left alone. It refuses
to build a version older than one already listed. Fails with a message (exit 1) when a step fails.
"""

import argparse
import json
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import build_extension  # noqa: E402  (scripts/build_extension.py, after the path is set)
from build_extension import BuildFailed  # noqa: E402

ROOT = build_extension.ROOT
ARCHIVE = "archive"
INDEX = "index.json"


def version_key(version, where):
    """(major, minor, patch) of a manifest's ``version`` ("1.2.3", a pre-release or build suffix ignored)."""
    found = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)(?:[-+].*)?", version)
    if not found:
        raise BuildFailed(f"{where}: expected a version like 1.2.3, got {version!r}")
    return tuple(int(part) for part in found.groups())


def manifest_of(path):
    """(id, version) of the extension zip ``path``."""
    try:
        with zipfile.ZipFile(path) as archive:
            manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
    except (OSError, KeyError, zipfile.BadZipFile, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BuildFailed(f"{path}: expected an extension zip with a blender_manifest.toml, "
                          f"could not read one: {exc}") from exc
    return manifest.get("id"), manifest.get("version")


def publish(platforms, out, cache, html=False):
    """Build the zips of ``platforms`` into the repository folder ``out`` and write its index;
    returns (the new zips, the zips moved to ``out/archive``, the index's path)."""
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    ident, version = manifest["id"], manifest["version"]
    key = version_key(version, ROOT / "blender_manifest.toml")
    out.mkdir(parents=True, exist_ok=True)
    listed = {}
    for path in sorted(out.glob("*.zip")):
        other_id, other_version = manifest_of(path)
        if other_id == ident:
            listed[path] = other_version
            if version_key(other_version, path) > key:
                raise BuildFailed(f"{out}: expected versions of {ident} older than or equal to the one being "
                                  f"built ({version}), found {other_version} ({path.name})")
    with tempfile.TemporaryDirectory(prefix=".build-", dir=out) as scratch:
        built = build_extension.build(platforms, pathlib.Path(scratch), cache)
        archived = []
        for path, other_version in listed.items():
            if other_version == version:
                path.unlink()
            else:
                (out / ARCHIVE).mkdir(exist_ok=True)
                archived.append(pathlib.Path(shutil.move(path, out / ARCHIVE / path.name)))
        zips = [pathlib.Path(shutil.move(path, out / path.name)) for path in built.values()]
    command = [sys.executable, str(build_extension.blender_ext()), "server-generate", "--repo-dir", str(out)]
    run = subprocess.run(command + (["--html"] if html else []), capture_output=True, text=True)
    if run.returncode != 0:
        raise BuildFailed(f"blender_ext server-generate: {(run.stdout + run.stderr).strip()}")
    index = out / INDEX
    try:
        data = json.loads(index.read_text())["data"]
    except (OSError, ValueError, KeyError) as exc:
        raise BuildFailed(f"{index}: expected the listing server-generate writes, could not read it: {exc}") from exc
    urls = {entry.get("archive_url") for entry in data}
    unlisted = [path.name for path in sorted(out.glob("*.zip")) if f"./{path.name}" not in urls]
    if unlisted:
        raise BuildFailed(f"{index}: expected every zip of the folder listed, these are not: {', '.join(unlisted)} "
                          f"({(run.stdout + run.stderr).strip()})")
    return zips, archived, index


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--platforms", default=",".join(build_extension.PLATFORMS),
                        help=f"comma-separated, from {', '.join(build_extension.PLATFORMS)} (default: all)")
    parser.add_argument("--out", default=str(ROOT / "dist" / "repo"), help="the repository folder")
    parser.add_argument("--wheels", default=str(ROOT / "build" / "wheels"), help="download cache for the wheels")
    parser.add_argument("--html", action="store_true", help="write index.html too (a page listing the extensions)")
    args = parser.parse_args()
    platforms = [p.strip() for p in args.platforms.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in build_extension.PLATFORMS]
    if unknown or not platforms:
        parser.error(f"--platforms: expected names from {', '.join(build_extension.PLATFORMS)}, got {args.platforms!r}")
    try:
        zips, archived, index = publish(platforms, pathlib.Path(args.out), pathlib.Path(args.wheels), args.html)
    except BuildFailed as exc:
        print(f"build_repo: error: {exc}", file=sys.stderr)
        sys.exit(1)
    for path in zips:
        print(f"{path} ({path.stat().st_size / 2**20:.1f} MiB), validated")
    for path in archived:
        print(f"{path}: an older version, moved out of the listing")
    print(f"{index} ({index.stat().st_size / 1024:.1f} KiB): lists {len(json.loads(index.read_text())['data'])} zips")
    if args.html:
        print(f"{index.with_name('index.html')}")


if __name__ == "__main__":
    main()
