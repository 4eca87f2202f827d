# SPDX-License-Identifier: GPL-3.0-or-later
"""Pure NumPy radiosity core: no bpy here, every stage testable in plain Python.

The bake is :data:`pipeline.STAGES`, run in this order over one ``pipeline.BakeContext``; each
stage lives in the package that owns its work, so the folders read as the data flow:

==============  =========================  ===================================================
stage           package                    entry function
==============  =========================  ===================================================
patches         ``mesh/``                  ``mesh.stage.patch_stage``
refine          ``mesh/``                  ``mesh.refine.refine_stage``
form_factors    ``form_factors/``          ``form_factors.stage.form_factor_stage``
direct          ``light/``                 ``light.stage.direct_stage``
solve           ``solve/``                 ``solve.stage.solve_stage``
vertices        ``output/``                ``output.stage.vertex_stage``
estimate        ``output/``                ``output.estimate.estimate_stage``
==============  =========================  ===================================================

Beside the stages: ``settings.py`` (every setting, once), ``pipeline.py`` (the stage list and
:func:`pipeline.bake`), ``rays.py`` (the ray scenes every stage casts into), ``hemisphere.py``
(rays over a point's hemisphere: the sky's share, the open share), ``builtin_scenes.py``
(the demo Cornell box and closed-form scenes as arrays), ``formats/`` (file formats without
Blender: glTF made valid), ``util/`` (no radiosity knowledge: sparse rows and their products,
nearest neighbours, distinct rows, geometry, sampling and the luminance weights) and
``runtime/`` (how a bake runs: errors, progress and cancellation, workers, caches, the time
forecast).
"""
