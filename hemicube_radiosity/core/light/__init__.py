# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``direct``: light that reaches a surface straight from emissive patches (``emitters``),
lamps (``lamps``) and the world, in closed form (``polygon_ff``, over group outlines
``outline``) with shadow rays (``stage``)."""
