# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender scene -> core arrays: meshes (``scene``), what a render sees and where
(``visibility``), materials from their node values (``materials``) or as Cycles evaluates them
(``shading``), lamps and the world (``lights``)."""
