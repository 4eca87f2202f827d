# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``form_factors``: F by hemi-cubes rasterised in NumPy (``hemicube``: delta form factors
``deltaff``, pixel tables ``pixels``, faces and clipping ``frustum``, item and depth buffers
``raster``, grouped pieces drawn as outlines ``drawn``) or by Embree rays (``embree``), cached
per geometry (``stage.py`` chooses)."""
