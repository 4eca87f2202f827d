# SPDX-License-Identifier: GPL-3.0-or-later
"""Stages ``vertices`` and ``estimate``: radiosity at the vertices of the mesh that is written
(the output elements, the final gather, the paper's vertex rule, interpolation) and the bake's
estimated error."""
