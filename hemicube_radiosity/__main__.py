"""``python -m hemicube_radiosity bake|demo|batch ...`` with the bpy module (see :mod:`.blender.cli.main`).

From any directory: ``PYTHONPATH=/path/to/repo /path/to/repo/.venv/bin/python -m
hemicube_radiosity ...``, or the repository's ``bin/hemicube-radiosity`` wrapper, which does that.
"""
import os
import sys


def _exit_hard_needed(bpy):
    """The bpy module of Blender 4.2 crashes (SIGSEGV, exit status 139) while the interpreter shuts
    down once the glTF exporter has run, after every file was written and closed. Seen with bpy
    4.2.23, not with 4.5.15 or 5.0.1; 4.3 and 4.4 are untested, so they are treated as 4.2."""
    return bpy.app.version < (4, 5, 0) and "io_scene_gltf2" in sys.modules


def _main():
    try:
        import bpy
    except ImportError:
        print("hemicube_radiosity: error: the 'bpy' module is needed: pip install bpy (Python 3.11), "
              "or run inside Blender with: blender -b -c hemicube_radiosity ...", file=sys.stderr)
        return 1
    from .blender.cli.main import flush_c_stdio, main

    code = main()
    if {"-q", "--quiet"} & set(sys.argv[1:]):
        # Quiet to the end: Blender 4.5 prints "Error: Not freed memory blocks" on stdout while
        # the interpreter shuts down, after the command has returned.
        sys.stdout.flush()
        flush_c_stdio()
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    if _exit_hard_needed(bpy):
        # Skip the interpreter's teardown that crashes (see above): flush what was printed, then
        # leave with the command's own status. Outputs are complete by now (written under a
        # temporary name and renamed); Blender's session temp folder is removed here instead.
        import shutil

        if bpy.app.tempdir and os.path.basename(os.path.normpath(bpy.app.tempdir)).startswith("blender_"):
            shutil.rmtree(bpy.app.tempdir, ignore_errors=True)
        sys.stdout.flush()
        sys.stderr.flush()
        flush_c_stdio()
        os._exit(code)
    return code


if __name__ == "__main__":
    sys.exit(_main())
