"""What `make bench` runs: every benchmark in turn, then bench/report.py, which writes
docs/performance.md (and docs/img/perf_*.png) from the JSON each benchmark saved in bench/out/.

    make bench                            # full run (~30 min on 2 cores; Cycles references cached)
    make bench BENCH_ARGS=--quick         # smoke run (~11 min)
    make bench BENCH_ARGS=--report-only   # the report alone, from bench/out/ (runs nothing)

The benchmarks: form-factor speed (``bench_formfactors.py``), the batch speed-up (``bench_batch.py``:
-j 2 against -j 1), the stages on 1 and 2 workers (``bench_parallel.py``), the tessellation sweep
(``bench_dense.py``), a dense room's relight (``bench_relight_dense.py``), Suzanne subdivided in the
Cornell box (``bench_curved.py``), then speed against error (``speed_vs_error.py``, which gets the
other arguments; ``--quick`` goes to every script), then the real scenes of ../shared/scenes
(``real_scenes.py``: skipped with one line where that folder is absent; ``--quick``: two small ones), a
real scene's lightmaps against Cycles' image bake (``lightmap_real.py``; not with ``--quick``) and their
pictures beside Cycles' (``gallery.py``: docs/gallery.md, ~14 min, ``--quick`` ~2; skipped likewise).
Exits non-zero when a script fails; targets that do not hold are printed, not failed (they are
measurements, not tests).
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
BENCHES = ("bench_formfactors.py", "bench_batch.py", "bench_parallel.py", "bench_dense.py",
           "bench_relight_dense.py", "bench_curved.py")


def run(script, args):
    t = time.perf_counter()
    print(f"\n##### {os.path.basename(script)} {' '.join(args)}", flush=True)
    rc = subprocess.call([sys.executable, script, *args], cwd=os.path.dirname(HERE))
    print(f"##### {os.path.basename(script)}: exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
    return rc


def main(argv):
    quick = ["--quick"] if "--quick" in argv else []
    if "--report-only" in argv:
        return run(os.path.join(HERE, "report.py"), quick)
    t = time.perf_counter()
    rc = 0
    for name in BENCHES:
        rc |= run(os.path.join(HERE, name), quick)
    rc |= run(os.path.join(HERE, "speed_vs_error.py"), argv)
    rc |= run(os.path.join(HERE, "real_scenes.py"), quick)
    if not quick:
        rc |= run(os.path.join(HERE, "lightmap_real.py"), [])
    rc |= run(os.path.join(HERE, "gallery.py"), quick)
    rc |= run(os.path.join(HERE, "report.py"), quick)
    print(f"\nmake bench: {time.perf_counter() - t:.0f} s", flush=True)
    return 1 if rc else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
