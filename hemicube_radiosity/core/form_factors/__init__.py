# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``form_factors``: F by hemi-cubes rasterised in NumPy (delta form factors, pixel
tables, item and depth buffers, grouped pieces drawn as outlines) or by Embree rays, cached per
geometry (``stage.py`` chooses)."""
