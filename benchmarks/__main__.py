"""Run every benchmark: ``python -m benchmarks`` (``make bench``)."""

from . import bench_feasibility, bench_models

for bench in (bench_models, bench_feasibility):
    print(f"== {bench.__name__} ==")
    bench.main()
