"""What `make bench` runs: the form-factor micro-benchmark (if present), the batch speed-up
(``bench_batch.py``: -j 2 against -j 1), the stages on 1 and 2 worker threads
(``bench_parallel.py``), the tessellation sweep (``bench_dense.py``), a dense room's relight
(``bench_relight_dense.py``), Suzanne subdivided in the Cornell box (``bench_curved.py``), then
speed vs error.

    make bench                       # full run (~30 min on 2 cores; Cycles references cached)
    make bench BENCH_ARGS=--quick    # smoke run (~3 min)

Arguments are passed to bench/speed_vs_error.py (``--quick`` also to the others). Exits non-zero when a benchmark script fails; targets that do not hold are printed,
not failed (they are measurements, not tests).
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def run(script, args):
    t = time.perf_counter()
    print(f"\n##### {os.path.basename(script)} {' '.join(args)}", flush=True)
    rc = subprocess.call([sys.executable, script, *args], cwd=os.path.dirname(HERE))
    print(f"##### {os.path.basename(script)}: exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
    return rc


def main(argv):
    rc = 0
    ff = os.path.join(HERE, "bench_formfactors.py")
    if os.path.exists(ff):
        rc |= run(ff, ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "bench_batch.py"), ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "bench_parallel.py"), ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "bench_dense.py"), ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "bench_relight_dense.py"), ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "bench_curved.py"), ["--quick"] if "--quick" in argv else [])
    rc |= run(os.path.join(HERE, "speed_vs_error.py"), argv)
    return 1 if rc else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
