"""Form-factor speed: NumPy hemi-cube rasteriser (and Embree through the same pixels, if present).

Closed box rooms of about 500, 2,000 and 8,000 patches at resolutions 64 and 128; prints ms per
hemi-cube, total time and the size of F.  ``--quick`` skips the 8,000-patch rows.

    .venv/bin/python bench/bench_formfactors.py [--quick]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from hemicube_radiosity.core.hemicube import hemicube_form_factors  # noqa: E402
from hemicube_radiosity.core.patches import build_patches  # noqa: E402
from hemicube_radiosity.core.scenes import closed_box  # noqa: E402

# cells per side of a unit cube room: 6 n^2 patches
ROOMS = {"~500": 9, "~2000": 18, "~8000": 36}


def methods():
    """(name, function) pairs to time; Embree only when it can be imported."""
    out = [("numpy", hemicube_form_factors)]
    try:
        from hemicube_radiosity.core.embree_ff import embree_available, embree_hemicube_form_factors
    except ImportError:
        return out
    if embree_available():
        out.append(("embree", embree_hemicube_form_factors))
    return out


def time_one(fn, patches, resolution):
    t0 = time.perf_counter()
    F = fn(patches, resolution)
    return time.perf_counter() - t0, F


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 8,000-patch room")
    args = ap.parse_args(argv)
    rooms = {k: v for k, v in ROOMS.items() if not (args.quick and k == "~8000")}
    print(f"{'room':>6} {'patches':>7} {'R':>4} {'method':>7} {'ms/hemicube':>11} {'total s':>8} "
          f"{'nnz':>10} {'F MB':>7} {'max|rowsum-1|':>13}")
    for label, n in rooms.items():
        patches = build_patches(closed_box(), 1.0 / n)
        for R in (64, 128):
            for name, fn in methods():
                dt, F = time_one(fn, patches, R)
                err = abs(F.row_sums() - 1).max()
                print(f"{label:>6} {len(patches):>7} {R:>4} {name:>7} {1e3 * dt / len(patches):>11.2f} "
                      f"{dt:>8.2f} {F.nnz:>10} {F.nbytes / 1e6:>7.1f} {err:>13.1e}", flush=True)


if __name__ == "__main__":
    main()
