"""Run every benchmark: ``python -m benchmarks`` (``make bench``); ``python -m benchmarks NAME ...``
runs only those (models, feasibility, run, profile, ocp, ipopt, pruning, margins, suite, timor,
engines, search, costs, goals, mesh, nodes). RESULTS.md is rewritten at the end.

Like the package's workers, the benchmarks' own process uses one BLAS thread, so that a solve
timed here is the solve a run does."""

import sys

from modular_robots.execution import single_threaded_blas

from . import (
    bench_costs,
    bench_engines,
    bench_feasibility,
    bench_goals,
    bench_ipopt,
    bench_margins,
    bench_mesh,
    bench_models,
    bench_nodes,
    bench_ocp,
    bench_profile,
    bench_pruning,
    bench_run,
    bench_search,
    bench_suite,
    bench_timor,
    results_md,
)

BENCHES = {
    "models": bench_models,
    "feasibility": bench_feasibility,
    "run": bench_run,
    "profile": bench_profile,
    "ocp": bench_ocp,
    "ipopt": bench_ipopt,
    "pruning": bench_pruning,
    "margins": bench_margins,
    "suite": bench_suite,
    "timor": bench_timor,
    "engines": bench_engines,
    "search": bench_search,
    "costs": bench_costs,
    "goals": bench_goals,
    "mesh": bench_mesh,
    "nodes": bench_nodes,
}

with single_threaded_blas():
    for name in sys.argv[1:] or list(BENCHES):
        print(f"== {name} ==")
        BENCHES[name].main()
results_md.main()
