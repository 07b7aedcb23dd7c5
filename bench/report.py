"""What a benchmark's JSON carries besides its rows: the command that measured it, when, on what
machine and with which versions, so the page made from it (scripts/benchmark_page.py) can say so;
and the Markdown table figures are shown in."""

import datetime
import importlib.metadata
import json
import os
import platform
import sys

PACKAGES = ("numpy", "scipy", "fast-simplification", "bpy", "libigl")


def metadata(command):
    """Dict: command, date (UTC), machine (platform, cores), versions of Python and PACKAGES."""
    versions = {"python": platform.python_version()}
    for package in PACKAGES:
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            pass
    return {"command": command, "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores", "versions": versions}


def save(path, rows, registered=None):
    """Write ``rows`` (any JSON value) to ``path`` with the :func:`metadata` of this run's command
    line, and ``registered`` in it when given: whether the add-on ran registered, as an artist has
    it (bench/addon.py)."""
    command = "python " + " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:])
    meta = metadata(command)
    if registered is not None:
        meta["registered"] = bool(registered)
    with open(path, "w", encoding="utf-8") as handle:
        json.dump({"meta": meta, "rows": rows}, handle, indent=2)


def table(columns, rows):
    """Markdown table: ``columns`` [(title, function of a row -> text)], one line per row."""
    lines = ["| " + " | ".join(title for title, _ in columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(row) for _, cell in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"
