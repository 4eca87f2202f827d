"""Form-factor speed: NumPy hemi-cube rasteriser (and Embree through the same pixels, if present).

Closed box rooms of about 500, 2,000 and 8,000 patches at resolutions 64 and 128; prints ms per
hemi-cube (wall clock), total time, the size of F and CPU ms per hemi-cube (steadier than the
wall clock when other jobs share the machine).  ``--quick`` skips the 8,000-patch rows.
``--baseline FILE`` also times another version of ``core/form_factors/hemicube.py`` (e.g. a copy of an older
commit kept outside the repo) in the same run, and reports how far its F is from the current one.
Results go to bench/out/formfactors.json.

    .venv/bin/python bench/bench_formfactors.py [--quick] [--baseline /tmp/hemicube_old.py]
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors  # noqa: E402
from hemicube_radiosity.core.mesh.subdivide import build_patches  # noqa: E402
from hemicube_radiosity.core.builtin_scenes import closed_box  # noqa: E402

# cells per side of a unit cube room: 6 n^2 patches
ROOMS = {"~500": 9, "~2000": 18, "~8000": 36}


def load_baseline(path):
    """``hemicube_form_factors`` of another version of core/form_factors/hemicube.py, loaded inside the package
    (so its relative imports resolve)."""
    spec = importlib.util.spec_from_file_location("hemicube_radiosity.core._bench_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.hemicube_form_factors


def methods(baseline=None):
    """(name, function) pairs to time; Embree only when it can be imported."""
    out = [("numpy", hemicube_form_factors)]
    if baseline:
        out.append(("base", load_baseline(baseline)))
    from hemicube_radiosity.core.form_factors.embree import embree_hemicube_form_factors
    from hemicube_radiosity.core.rays import embree_available

    if embree_available():
        out.append(("embree", embree_hemicube_form_factors))
    return out


def time_one(fn, patches, resolution):
    t0, c0 = time.perf_counter(), time.process_time()
    F = fn(patches, resolution)
    return time.perf_counter() - t0, time.process_time() - c0, F


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 8,000-patch room")
    ap.add_argument("--baseline", metavar="FILE",
                    help="another hemicube.py to time as 'base' (and compare F with)")
    args = ap.parse_args(argv)
    rooms = {k: v for k, v in ROOMS.items() if not (args.quick and k == "~8000")}
    print(f"{'room':>6} {'patches':>7} {'R':>4} {'method':>7} {'ms/hemicube':>11} {'total s':>8} "
          f"{'nnz':>10} {'F MB':>7} {'max|rowsum-1|':>13} {'cpu ms/hc':>9}"
          + (f" {'max|F-F_numpy|':>14}" if args.baseline else ""))
    rows = []
    for label, n in rooms.items():
        patches = build_patches(closed_box(), 1.0 / n)
        for R in (64, 128):
            ref = None
            for name, fn in methods(args.baseline):
                dt, cpu, F = time_one(fn, patches, R)
                err = abs(F.row_sums() - 1).max()
                line = (f"{label:>6} {len(patches):>7} {R:>4} {name:>7} {1e3 * dt / len(patches):>11.2f} "
                        f"{dt:>8.2f} {F.nnz:>10} {F.nbytes / 1e6:>7.1f} {err:>13.1e} "
                        f"{1e3 * cpu / len(patches):>9.2f}")
                if args.baseline:
                    ref = F if ref is None else ref
                    line += f" {max_difference(ref, F):>14.1e}"
                print(line, flush=True)
                rows.append({"room": label, "patches": len(patches), "resolution": R, "method": name,
                             "ms_per_hemicube": 1e3 * dt / len(patches), "seconds": dt, "nnz": int(F.nnz),
                             "f_mb": F.nbytes / 1e6, "rowsum_error": float(err),
                             "cpu_ms_per_hemicube": 1e3 * cpu / len(patches)})
    os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
    with open(os.path.join(HERE, "out", "formfactors.json"), "w") as f:
        json.dump({"quick": args.quick, "rows": rows}, f, indent=1)


def max_difference(A, B):
    """Largest |A_ij - B_ij| over the union of the two sparsity patterns."""
    d = A.to_dense() if A.shape[0] <= 4000 else None
    if d is None:  # too big for dense: compare row by row
        return max((np.abs(_row(A, i) - _row(B, i)).max() for i in range(A.shape[0])), default=0.0)
    return float(np.abs(d - B.to_dense()).max())


def _row(F, i):
    out = np.zeros(F.shape[1])
    cols, vals = F.row(i)
    out[cols] = vals
    return out


if __name__ == "__main__":
    main()
