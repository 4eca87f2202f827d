"""``python -m hemicube_radiosity bake|demo ...`` with the bpy module (see :mod:`.cli`)."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
