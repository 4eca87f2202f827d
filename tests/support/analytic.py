"""Closed-form form factors (Siegel & Howell's catalogue): the independent truth the form-factor
tests compare against. Pure NumPy, no project code."""
import numpy as np


def parallel_rectangles(a=1.0, b=1.0, c=1.0):
    """Directly opposed parallel a x b rectangles a distance c apart (unit squares: 0.1998)."""
    X, Y = a / c, b / c
    return 2 / (np.pi * X * Y) * (
        np.log(np.sqrt((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)))
        + X * np.sqrt(1 + Y * Y) * np.arctan(X / np.sqrt(1 + Y * Y))
        + Y * np.sqrt(1 + X * X) * np.arctan(Y / np.sqrt(1 + X * X))
        - X * np.arctan(X) - Y * np.arctan(Y))


def perpendicular_rectangles(w=1.0, h=1.0, l=1.0):
    """From a w x l rectangle to an h x l rectangle sharing the edge l (unit squares: 0.2000)."""
    W, H = w / l, h / l
    S = W * W + H * H
    log_term = np.log((1 + W * W) * (1 + H * H) / (1 + S)
                      * (W * W * (1 + S) / ((1 + W * W) * S)) ** (W * W)
                      * (H * H * (1 + S) / ((1 + H * H) * S)) ** (H * H))
    return (W * np.arctan(1 / W) + H * np.arctan(1 / H) - np.sqrt(S) * np.arctan(1 / np.sqrt(S))
            + 0.25 * log_term) / (np.pi * W)


def point_under_rectangle_corner(a, b, c):
    """From a point facing a parallel a x b rectangle c away, under one of its corners."""
    A, B = a / c, b / c
    return (A / np.hypot(1, A) * np.arctan(B / np.hypot(1, A))
            + B / np.hypot(1, B) * np.arctan(A / np.hypot(1, B))) / (2 * np.pi)


def object_factor(patches, F, src=0, dst=1):
    """Area-weighted factor from object ``src`` to object ``dst`` out of a patch matrix."""
    D = F.to_dense()
    a, b = patches.owner == src, patches.owner == dst
    A = patches.areas[a]
    return float((A[:, None] * D[np.ix_(a, b)]).sum() / A.sum())
