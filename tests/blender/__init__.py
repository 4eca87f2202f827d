"""Tests of the Blender layer (need bpy): the add-on, CLI, batch, glTF, packaging, the viewer and
the comparisons with Cycles."""
