# SPDX-License-Identifier: GPL-3.0-or-later
"""Stages ``patches`` and ``refine``: the input meshes as patches (``patches`` data model,
``ngons``, ``subdivide``), small faces grouped into clusters, cuts along contact lines, patches
split where the direct light changes abruptly (``refine``), and the output element mesh cut at
the detail size (``elements``), made early on a spare core."""
