# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender scene -> core arrays: meshes (``scene``), materials as Cycles evaluates them
(``shading``), lamps and the world (``lights``)."""
