"""Pure NumPy radiosity core: no bpy here, every stage testable in plain Python.

Stages (data flows one way): patches -> form factors -> radiosities -> vertex radiosities.
"""
