"""Skin Detach: deform huge detail meshes through a small proxy, detail kept intact."""
