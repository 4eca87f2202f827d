"""``python -m hemicube_radiosity bake|demo ...`` with the bpy module (see :mod:`.blender.cli`)."""
import sys


def _main():
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("hemicube_radiosity: error: the 'bpy' module is needed: pip install bpy (Python 3.11), "
              "or run inside Blender with: blender -b -c hemicube_radiosity ...", file=sys.stderr)
        return 1
    from .blender.cli import main

    return main()


if __name__ == "__main__":
    sys.exit(_main())
