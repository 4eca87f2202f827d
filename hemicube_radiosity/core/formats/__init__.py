# SPDX-License-Identifier: GPL-3.0-or-later
"""File formats without Blender: the baked glTF made valid (COLOR_0 in 0..1, HDR kept)."""
