"""The batch bake from a checkout: the same command line as the add-on's own
``skin_detach_addon.bake_cli`` (which a farm worker with the extension installed runs).

Inside Blender:      blender --background scene.blend --python scripts/bake.py -- ARGS
With the bpy module: python scripts/bake.py --blend scene.blend ARGS
(python scripts/bake.py --help lists ARGS.)
"""

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

if __name__ == "__main__":
    import bpy  # noqa: F401  (first: the bpy module makes mathutils importable)

    from skin_detach_addon import bake_cli
    bake_cli.main()
