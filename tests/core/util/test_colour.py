"""The shared luminance weights against their definition: the Y row of the Rec. 709 RGB -> XYZ
matrix, derived from the standard's primaries and D65 white point (CIE xy), rounded as the
standard prints them (four places).

    .venv/bin/python -m pytest -q tests/core/util/test_colour.py
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.util.colour import LUMA


def _rec709_y_row():
    """Y of each primary scaled so R = G = B = 1 is the white point with Y = 1."""
    xy = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])          # R, G, B primaries
    white = np.array([0.3127, 0.3290])                                  # D65
    xyz = lambda c: np.array([c[0] / c[1], 1.0, (1.0 - c[0] - c[1]) / c[1]])
    primaries = np.column_stack([xyz(c) for c in xy])                   # (3, 3) columns X Y Z
    scale = np.linalg.solve(primaries, xyz(white))
    return primaries[1] * scale


def test_luma_is_the_rec709_y_row():
    y = _rec709_y_row()
    assert abs(y.sum() - 1.0) < 1e-12
    assert LUMA.shape == (3,) and LUMA.dtype == np.float64
    assert np.array_equal(LUMA, np.round(y, 4))


def test_luma_of_white_is_one():
    assert abs(float(np.ones(3) @ LUMA) - 1.0) < 1e-12
