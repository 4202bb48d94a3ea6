"""Run every benchmark: ``python -m benchmarks`` (``make bench``); ``python -m benchmarks NAME ...``
runs only those (models, feasibility, ocp, pruning). RESULTS.md is rewritten at the end."""

import sys

from . import bench_feasibility, bench_models, bench_ocp, bench_pruning, results_md

BENCHES = {"models": bench_models, "feasibility": bench_feasibility, "ocp": bench_ocp, "pruning": bench_pruning}

for name in sys.argv[1:] or list(BENCHES):
    print(f"== {name} ==")
    BENCHES[name].main()
results_md.main()
