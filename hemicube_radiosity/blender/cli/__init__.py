# SPDX-License-Identifier: GPL-3.0-or-later
"""The command line: ``python -m hemicube_radiosity`` and ``blender -c hemicube_radiosity``.
``main`` runs ``bake`` and ``demo``, ``batch`` runs many bakes in worker processes, ``parser``
holds the options (one per bake setting) and the error type."""
