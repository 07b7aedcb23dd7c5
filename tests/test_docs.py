"""README.md and docs/ name only things that exist: API functions, operators, the bake CLI's and the
scripts' options, files and make targets (a name removed from the code fails here)."""

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Blender's and other tools' own options that the pages pass on the same command lines.
FOREIGN_OPTIONS = {"--background", "--python", "--python-expr", "--python-exit-code", "--command", "--repo", "--name",
                   "--directory", "--enable", "--help", "--split-platforms"}


def text(page):
    return page.read_text(encoding="utf-8")


def code(page):
    """Every fenced block's lines, indented block's lines and inline code span of ``page``."""
    body = text(page)
    spans = re.findall(r"```[a-z]*\n(.*?)```", body, flags=re.S)
    spans += re.findall(r"(?m)^(?: {4}|\t)(\S.*)$", body)
    spans += re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", body, flags=re.S))
    return spans


def test_the_pages_exist_and_the_readme_is_short_with_the_essentials_first():
    assert {p.name for p in PAGES} >= {"README.md", "index.md", "addon.md", "scripting.md", "farm.md", "how-it-works.md",
                                        "benchmarks.md"}
    lines = text(ROOT / "README.md").splitlines()
    assert len(lines) <= 250
    first = "\n".join(lines[:100])
    for heading in ("## Install", "## Two commands", "## The add-on in five steps"):
        assert heading in first
    assert "    make demo" in first and "    make test" in first


def test_the_manifest_website_is_a_url_or_absent():
    manifest = (ROOT / "blender_manifest.toml").read_text()
    found = re.search(r'(?m)^website = "([^"]+)"', manifest)
    assert found is None or re.match(r"https?://", found.group(1)), found.group(1)


def test_every_api_name_in_the_pages_exists():
    pytest.importorskip("bpy")
    from skin_detach_addon import api
    named = {name for page in PAGES for span in code(page) for name in re.findall(r"(?<![/\w])api\.([A-Za-z_]\w*)", span)} - {"py"}
    assert named, "the pages name no API function"
    assert not sorted(n for n in named if not hasattr(api, n))
    scripting = text(ROOT / "docs" / "scripting.md")
    section = scripting[scripting.index("## Scripting API"):scripting.index("## Core API")]
    called = set(re.findall(r"`([a-z_]+)\(", section))
    assert called and not sorted(n for n in called if not (hasattr(api, n) or hasattr(api.DragSession, n)))


def test_every_operator_named_in_the_pages_is_registered():
    pytest.importorskip("bpy")
    from skin_detach_addon.ui.operators import CLASSES
    registered = {cls.bl_idname for cls in CLASSES}
    named = {m for page in PAGES for m in re.findall(r"\bskin_detach\.([a-z_]+)\b(?!\.py)", text(page))}
    assert not sorted(f"skin_detach.{n}" for n in named if f"skin_detach.{n}" not in registered)
    labels = {cls.bl_label for cls in CLASSES}
    addon = text(ROOT / "docs" / "addon.md")
    for label in ("Build", "Add Handle", "Add Anchor", "Drag Handle", "Reset", "Clear Skin"):
        assert any(full.startswith(label) for full in labels) and f"**{label}" in addon


def bake_options():
    from skin_detach_addon import bake_cli
    return {option for action in bake_cli.parser()._actions for option in action.option_strings}


def test_every_bake_option_in_the_pages_is_the_clis():
    known = bake_options()
    named = set()
    for page in PAGES:
        for span in code(page):
            if "bake.py" in span or "bake_cli" in span:
                tail = span.split(" -- ", 1)[1] if " -- " in span else span.split("bake.py", 1)[-1]
                named.update(re.findall(r"(?<![\w-])(--[a-z][a-z-]*)", tail))
            elif span.startswith("--") and page.name in ("farm.md", "README.md"):
                named.add(re.match(r"--[a-z][a-z-]*", span).group(0))
    named -= FOREIGN_OPTIONS
    assert "--frames" in named and "--verify" in named
    assert not sorted(named - known)


def test_every_script_option_file_and_make_target_named_exists():
    makefile = (ROOT / "Makefile").read_text()
    for page in PAGES:
        for span in code(page):
            for path in re.findall(r"\b((?:scripts|farm|docs|bench|tests|skin_detach_addon)/[\w./-]*\w)", span):
                assert (ROOT / path).exists(), f"{page.name}: {path}"
            for path in re.findall(r"(?<![\w/])(core/[\w./-]*\w)", span):  # the add-on's core, named short
                assert (ROOT / "skin_detach_addon" / path).exists(), f"{page.name}: {path}"
            for target in re.findall(r"\bmake ([a-z0-9-]+)\b", span):
                assert re.search(rf"(?m)^{target}:", makefile), f"{page.name}: make {target}"
            script = re.search(r"\bscripts/(\w+)\.py\b(.*)", span)
            if script and script.group(1) not in ("bake",):
                source = (ROOT / "scripts" / f"{script.group(1)}.py").read_text()
                for option in re.findall(r"(?<![\w-])(--[a-z][a-z-]*)", script.group(2)):
                    assert f'"{option}"' in source, f"{page.name}: scripts/{script.group(1)}.py {option}"


def test_a_removed_name_would_be_caught(monkeypatch):
    """The checks above see a removal: a CLI without --verify fails the option check."""
    from skin_detach_addon import bake_cli
    real = bake_cli.parser

    def without_verify():
        parser = real()
        parser._actions = [a for a in parser._actions if "--verify" not in a.option_strings]
        return parser
    monkeypatch.setattr(bake_cli, "parser", without_verify)
    with pytest.raises(AssertionError):
        test_every_bake_option_in_the_pages_is_the_clis()


def test_the_benchmark_page_is_generated_from_the_results():
    import subprocess
    import sys
    page = ROOT / "docs" / "benchmarks.md"
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "benchmark_page.py"), "--check"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stdout + run.stderr      # the committed page is the generated one
    for section in ("Command: `python scripts/benchmark_drag.py", "Command: `python scripts/benchmark_quality.py",
                    "Command: `python scripts/benchmark_scale.py"):
        assert section in text(page)
