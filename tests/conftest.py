import pathlib

import numpy as np
import pytest

from skin_detach_addon.core.obj_io import read_obj

DATA = pathlib.Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def bundled():
    """Loader of the bundled meshes by name (cached): (vertices, triangles)."""
    cache = {}

    def load(name):
        if name not in cache:
            cache[name] = read_obj(DATA / f"{name}.obj")
        return cache[name]

    return load


def diagonal(points):
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
