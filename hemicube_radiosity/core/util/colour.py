# SPDX-License-Identifier: GPL-3.0-or-later
"""Colour helpers with no radiosity knowledge.

:data:`LUMA` (3,) float64, dimensionless: the Rec. 709 / sRGB luminance weights of linear R, G,
B (ITU-R BT.709; they sum to 1). ``rgb @ LUMA`` maps an (..., 3) field of radiance,
irradiance or reflectance to its luminance in the same unit, (...). Every module that weighs
colours by luminance imports it from here (``tests/test_layout.py`` keeps the weights written
once).
"""
from __future__ import annotations

import numpy as np

__all__ = ["LUMA"]

LUMA = np.array([0.2126, 0.7152, 0.0722])
LUMA.setflags(write=False)
