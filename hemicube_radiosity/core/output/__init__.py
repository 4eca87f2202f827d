# SPDX-License-Identifier: GPL-3.0-or-later
"""Stages ``vertices`` and ``estimate``: radiosity at the vertices of the mesh that is written
(the final gather with its abrupt elements and what shines, the two sides of partitions, the
paper's vertex rule, interpolation; the output elements themselves are cut in
``mesh/elements.py``) and the bake's estimated error."""
