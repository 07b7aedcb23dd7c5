"""Benchmark and test helpers that do not ship in the add-on: bundled meshes and flat
subdivision (:mod:`.meshes`), the bend scenario (:mod:`.scenario`), quality figures
(:mod:`.quality`) and the full-resolution ARAP reference (:mod:`.arap`, libigl, dev-only).
Scripts and tests import it from the repository root; it imports the add-on, never the reverse.
"""
