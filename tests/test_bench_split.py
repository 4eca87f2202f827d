"""bench/error_split.py splits our error at Cycles' corners into the direct and the reflected part:
an error put into one part alone is found in that part alone, with its size and sign."""
import os
import sys

import numpy as np

from tests.support import ROOT

sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import error_split  # noqa: E402


def test_an_error_in_one_part_is_found_in_that_part():
    rng = np.random.default_rng(0)
    n = 1000
    rho = rng.uniform(0.1, 0.8, (n, 3))
    Dc, Ic = rng.uniform(0.0, 2.0, (n, 3)), rng.uniform(0.0, 0.5, (n, 3))
    ref, direct = rho * (Dc + Ic), rho * Dc
    mask = np.ones(n, bool)
    mask[:10] = False                                    # corners left out are not counted
    off = np.zeros((n, 3))
    off[::7] = 0.3                                       # a direct light 0.3 too bright at every 7th corner
    for D, I, wrong in ((Dc + off, Ic, "direct"), (Dc, Ic + off, "reflected")):
        s = error_split.split(ref, direct, rho * (D + I), rho, D, I, mask)
        assert np.allclose(s["d"], s["dd"] + s["di"])
        Y = np.asarray(error_split.sve.LUMA)
        mean = (ref[mask] @ Y).mean()
        expect = np.sqrt(np.mean(((rho * off) @ Y)[mask] ** 2)) / mean
        right = "rms_if_reflected_right" if wrong == "direct" else "rms_if_direct_right"
        other = "rms_if_direct_right" if wrong == "direct" else "rms_if_reflected_right"
        assert np.isclose(s["rms"], expect) and np.isclose(s[right], expect)
        assert s[other] < 1e-12
        bias = s["bias_direct"] if wrong == "direct" else s["bias_reflected"]
        assert np.isclose(bias, ((rho * off) @ Y)[mask].mean() / mean) and bias > 0
