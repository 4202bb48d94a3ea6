"""Run every benchmark: ``python -m benchmarks`` (``make bench``)."""

from . import bench_models

for bench in (bench_models,):
    print(f"== {bench.__name__} ==")
    bench.main()
