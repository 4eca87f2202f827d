# SPDX-License-Identifier: GPL-3.0-or-later
"""Stages ``patches`` and ``refine``: the input meshes cut into patches (data model, n-gons,
subdivision), small faces grouped into clusters, cuts along contact lines, and patches split
where the direct light changes abruptly."""
