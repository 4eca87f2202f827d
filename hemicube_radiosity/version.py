"""The add-on's version, kept equal to blender_manifest.toml's (tests/blender/test_manifest.py checks it)."""

__version__ = "0.1.0"
