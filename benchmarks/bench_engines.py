"""The engines side by side (issue 22): step B's throughput with ``process`` and ``ray`` on the
same CPUs, Ray's overhead per lockstep round of steps C+D, an estimate of the wall time on N
machines from the measured per-task costs, and the peak memory of ``enumerate``/``filter`` on
streamed spaces.

``python -m benchmarks engines`` measures the paper's 5 kg scenario (3108 compositions);
``python -m benchmarks.bench_engines --scenario S.yaml [--limit N]`` measures step B on another
scenario (e.g. IMPROV's 32,768-assembly study space), the rest unchanged.

Ray runs on a Ray instance of the benchmark's own with as many CPUs as the process engine has
workers (:func:`~modular_robots.ray_engine.start_local`, loopback only). Its workers are started
by a first short stream (reported as the cold start) before step B is timed: a cluster keeps its
workers between runs, while the process engine forks its workers from the already loaded parent
in milliseconds.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from modular_robots import load_scenario
from modular_robots.composition import count_compositions, enumerate_compositions
from modular_robots.execution import ExecutionSettings, ProcessEngine, ProcessExecutor, available_cores
from modular_robots.feasibility import filter_compositions
from modular_robots.pipeline import run_scenario

from ._common import RESULTS, commit, table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "paper-5kg.yaml"
SMALL = ROOT / "tests" / "data" / "small.yaml"
IMPROV_SCENARIO = ROOT / "benchmarks" / "improv-science2019.yaml"
CLI = str(Path(sys.executable).parent / "modular-robots")
#: The spaces the estimate is given for: the paper's, IMPROV's study space and its default space.
SPACES = {"paper": 3108, "IMPROV study": 32_768, "IMPROV default": 40_985_620}
MACHINES = (1, 4, 16, 64)


def _step_b(scenario, engine, limit: int | None) -> tuple[list, float]:
    compositions = itertools.islice(enumerate_compositions(scenario.catalog), limit)
    start = time.perf_counter()
    verdicts = [(v.composition.name, v.failed_test) for v in filter_compositions(scenario, compositions, engine=engine)]
    return verdicts, time.perf_counter() - start


def step_b(scenario, cpus: int, limit: int | None) -> list[dict]:
    """Assemblies per second of step B with each engine on ``cpus`` CPUs (same verdicts)."""
    from modular_robots import ray_engine

    process, process_wall = _step_b(scenario, ProcessEngine(cpus), limit)
    engine = ray_engine.RayEngine(None, cpus)
    start = time.perf_counter()
    engine.jobs  # noqa: B018 (connects: starts the Ray instance)
    started = time.perf_counter() - start
    _, cold_wall = _step_b(scenario, engine, 16 * cpus * 4)
    ray_verdicts, ray_wall = _step_b(scenario, engine, limit)
    assert ray_verdicts == process, "the engines disagree on step B"
    n = len(process)
    return [
        {"engine": "process", "cpus": cpus, "assemblies": n, "wall_s": process_wall, "per_s": n / process_wall},
        {
            "engine": "ray",
            "cpus": cpus,
            "assemblies": n,
            "wall_s": ray_wall,
            "per_s": n / ray_wall,
            "vs_process": (n / ray_wall) / (n / process_wall),
            "instance_start_s": started,
            "cold_first_stream_s": cold_wall,
        },
    ]


# -- lockstep rounds ------------------------------------------------------------------------------
class _Idle:
    """A job whose every step is free: what is left of a round is the engine's own cost."""

    def __init__(self, name: str):
        self.name, self.result = name, None

    def iterate(self):
        yield from itertools.count()

    def close(self) -> None:
        self.result = self.name


def _idle(context, spec) -> _Idle:
    return _Idle(spec)


def _rounds(executor, names: list[str], rounds: int) -> float:
    """Seconds per round of advancing every job once (after a first round that starts them)."""
    try:
        executor.advance(names)
        start = time.perf_counter()
        for _ in range(rounds):
            executor.advance(names)
        return (time.perf_counter() - start) / rounds
    finally:
        executor.shutdown()


def lockstep(cpus: int, candidates: int = 8, rounds: int = 200) -> dict:
    """An empty round trip per round: ``candidates`` idle jobs (the default admission), each
    advanced once per round, on worker processes and on Ray actors."""
    from modular_robots.ray_engine import RayExecutor

    names = [f"c{i}" for i in range(candidates)]
    process = _rounds(ProcessExecutor(_idle, None, names, names, cpus), names, rounds)
    ray = _rounds(RayExecutor(_idle, None, names, names), names, rounds)
    return {
        "candidates": candidates,
        "rounds": rounds,
        "process_round_ms": process * 1e3,
        "ray_round_ms": ray * 1e3,
        "ray_overhead_per_round_ms": (ray - process) * 1e3,
    }


def small_run(cpus: int) -> dict:
    """``run`` of the small scenario on both engines: the same candidates, iterations and rounds.
    The extra wall time per round of steps C+D is Ray's overhead in a real run: the first round
    (every actor's process starting and loading the package) apart from the others."""
    scenario = load_scenario(SMALL)
    ticks: dict[str, list[float]] = {"process": [], "ray": []}
    alive: list[int] = []

    def clock(engine: str):
        def on_progress(stage, figures):
            if stage == "feasibility":
                ticks[engine][:] = [time.perf_counter()]  # the last verdict: steps C+D start
            else:
                ticks[engine].append(time.perf_counter())
                if engine == "ray":
                    alive.append(figures["alive"])

        return on_progress

    with tempfile.TemporaryDirectory() as folder:
        process = run_scenario(scenario, Path(folder) / "p", jobs=cpus, on_progress=clock("process"))
        on_ray = dataclasses.replace(scenario, execution=ExecutionSettings("ray"))
        ray = run_scenario(on_ray, Path(folder) / "r", jobs=cpus, on_progress=clock("ray"))
    assert [(c.name, c.status, c.iterations) for c in ray.candidates] == [
        (c.name, c.status, c.iterations) for c in process.candidates
    ]
    rounds = {engine: [b - a for a, b in itertools.pairwise(t)] for engine, t in ticks.items()}
    later = (sum(rounds["ray"][1:]) - sum(rounds["process"][1:])) / (process.rounds - 1)
    return {
        "scenario": "small",
        "candidates": len(process.candidates),
        "rounds": process.rounds,
        "iterations": process.iterations,
        "process_steps_cd_s": process.seconds["optimization"],
        "ray_steps_cd_s": ray.seconds["optimization"],
        "ray_overhead_per_round_ms": (ray.seconds["optimization"] - process.seconds["optimization"])
        / process.rounds
        * 1e3,
        "ray_first_round_extra_s": rounds["ray"][0] - rounds["process"][0],
        "ray_overhead_per_later_round_ms": later * 1e3,
        "seconds_per_iteration": sum(c.seconds for c in process.candidates) / process.iterations,
        "alive_per_round": alive,
    }


def estimate(step_b_rows: list[dict], rounds: dict, run: dict, cores_per_machine: int = 2) -> list[dict]:
    """Wall time on N machines of ``cores_per_machine`` cores, from the measured per-task costs:
    step B's CPU seconds per assembly (the Ray run's, overhead included) spread over every core;
    steps C+D as the small run's lockstep (each round takes ceil(alive / cores) iterations of
    the measured mean cost, plus Ray's measured empty round)."""
    ray_b = next(r for r in step_b_rows if r["engine"] == "ray")
    cpu_per_assembly = ray_b["wall_s"] * ray_b["cpus"] / ray_b["assemblies"]
    rows = []
    for machines in MACHINES:
        cores = machines * cores_per_machine
        steps_cd = sum(
            math.ceil(alive / cores) * run["seconds_per_iteration"] + rounds["ray_round_ms"] / 1e3
            for alive in run["alive_per_round"]
            if alive
        )
        row = {"machines": machines, "cores": cores, "steps_cd_s (small)": steps_cd}
        for space, size in SPACES.items():
            row[f"step_b_s ({space}, {size:,})"] = size * cpu_per_assembly / cores
        rows.append(row)
    return rows


# -- memory of streamed spaces --------------------------------------------------------------------
_PEAK = (
    "import resource, subprocess, sys; "
    "done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, done.returncode)"
)


def _peak_mb(*command: str) -> tuple[float, float]:
    """Peak resident memory [MB] of ``command`` (the largest of its processes) and its wall time."""
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", _PEAK, *command], capture_output=True, text=True, check=True).stdout
    return int(out.split()[0]) / 1024, time.perf_counter() - start


def _wide_scenario(folder: Path, dof: int = 8, low: int = 2) -> Path:
    """The paper task on the paper catalogue widened to ``dof`` DOF (8: 671,844 assemblies; 9:
    4,031,076; from ``low`` = 9 to 9: the 3,359,232 nine-joint chains), in ``folder``."""
    paper = (ROOT / "scenarios" / "catalogs" / "paper.yaml").read_text()
    catalog = paper.replace("dof: [2, 5]", f"dof: [{low}, {dof}]")
    (folder / "wide.yaml").write_text(catalog)
    scenario = SCENARIO.read_text().replace("catalogs/paper.yaml", str(folder / "wide.yaml"))
    (folder / "wide-5kg.yaml").write_text(scenario)
    return folder / "wide-5kg.yaml"


def filter_prefix(limit: int, low: int = 2, space: str = "paper") -> dict:
    """Peak RSS of ``filter --limit LIMIT``, added to ``engines.json``'s memory rows. ``space``
    ``paper``: the paper space widened to 9 DOF (4,031,076 assemblies; ``low`` = 9: its nine-joint
    chains only, the longest models and 40 % survivors); ``improv``: IMPROV's 40,985,620-assembly
    space with ``improv-science2019.yaml``'s task
    (``python -m benchmarks.bench_engines --filter-prefix 1000000``: about half an hour on 2 cores).
    """
    with tempfile.TemporaryDirectory() as folder:
        if space == "improv":
            improv = ROOT / "scenarios" / "catalogs" / "improv.yaml"
            scenario = Path(folder) / "improv-default.yaml"
            scenario.write_text(
                IMPROV_SCENARIO.read_text().replace("../scenarios/catalogs/improv-science2019.yaml", str(improv))
            )
        else:
            scenario = _wide_scenario(Path(folder), dof=9, low=low)
        mb, wall = _peak_mb(
            CLI, "filter", str(scenario), "--jobs", "2", "--limit", str(limit),
            "--verdicts", str(Path(folder) / "prefix.jsonl"), "--max-compositions", "100000000",
        )  # fmt: skip
    if space == "improv":
        label = "IMPROV default space filter --limit"
    else:
        label = "filter --jobs 2 --limit (9 DOF)" if low == 2 else f"filter --jobs 2 --limit ({low} to 9 DOF)"
    row = {"command": label, "assemblies": limit, "peak_rss_mb": mb, "wall_s": wall, "commit": commit()}
    path = RESULTS / "engines.json"
    doc = json.loads(path.read_text())
    doc["memory"] = [r for r in doc["memory"] if not (r["command"] == label and r["assemblies"] == limit)]
    doc["memory"].append(row)
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return row


def memory(folder: Path) -> list[dict]:
    """Peak RSS of ``enumerate`` and ``filter`` as the space or the streamed prefix grows, on the
    paper catalogue widened to 8 DOF (671,844 assemblies) and on IMPROV (the 40,985,620-assembly
    space counted; its Science Robotics 2019 space listed and a prefix of it filtered)."""
    _wide_scenario(folder)
    space = sum(count_compositions(load_scenario(folder / "wide-5kg.yaml").catalog).values())
    rows = []
    for label, listed, options in (("enumerate --dof 6", 15_552, ["--dof", "6"]), ("enumerate", space, [])):
        mb, wall = _peak_mb(CLI, "enumerate", str(folder / "wide.yaml"), *options, "--max-compositions", "100000000")
        rows.append({"command": label, "assemblies": listed, "peak_rss_mb": mb, "wall_s": wall})
    for limit in (2_000, 20_000, 40_000):
        mb, wall = _peak_mb(
            CLI, "filter", str(folder / "wide-5kg.yaml"), "--jobs", "2", "--limit", str(limit),
            "--verdicts", str(folder / f"v{limit}.jsonl"), "--max-compositions", "100000000",
        )  # fmt: skip
        rows.append({"command": "filter --jobs 2 --limit", "assemblies": limit, "peak_rss_mb": mb, "wall_s": wall})
    # IMPROV: the 40,985,620-assembly space counted, and listed and filtered as streamed prefixes
    improv = ROOT / "scenarios" / "catalogs" / "improv.yaml"
    for label, listed, options in (
        ("IMPROV enumerate --count", 40_985_620, ["--count"]),
        ("IMPROV enumerate --dof 4", 25_600, ["--dof", "4"]),
        ("IMPROV Science2019 enumerate", 32_768, []),
    ):
        source = improv if "Science2019" not in label else ROOT / "scenarios" / "catalogs" / "improv-science2019.yaml"
        mb, wall = _peak_mb(CLI, "enumerate", str(source), *options, "--max-compositions", "100000000")
        rows.append({"command": label, "assemblies": listed, "peak_rss_mb": mb, "wall_s": wall})
    for limit in (200, 2_000):
        mb, wall = _peak_mb(
            CLI, "filter", str(IMPROV_SCENARIO), "--jobs", "2", "--limit", str(limit),
            "--verdicts", str(folder / f"improv{limit}.jsonl"),
        )  # fmt: skip
        rows.append(
            {"command": "IMPROV Science2019 filter --limit", "assemblies": limit, "peak_rss_mb": mb, "wall_s": wall}
        )
    return rows


def main(scenario_path: Path = SCENARIO, limit: int | None = None) -> None:
    from modular_robots import ray_engine

    scenario = load_scenario(scenario_path)
    cpus = min(2, available_cores())
    try:
        b = step_b(scenario, cpus, limit)
        rounds = lockstep(cpus)
        run = small_run(cpus)
    finally:
        ray_engine.disconnect()
    estimates = estimate(b, rounds, run, cores_per_machine=cpus)
    with tempfile.TemporaryDirectory() as folder:
        rss = memory(Path(folder))
    print(table(b))
    print(table([rounds]))
    print(table([{k: v for k, v in run.items() if k != "alive_per_round"}]))
    print(table(estimates))
    print(table(rss))
    write(
        "engines",
        b,
        {
            "scenario": scenario.name,
            "limit": limit,
            "lockstep": rounds,
            "small_run": run,
            "estimate": estimates,
            "memory": rss,
        },
    )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=SCENARIO)
    parser.add_argument("--limit", type=int, default=None, help="only the first LIMIT compositions")
    parser.add_argument(
        "--filter-prefix", type=int, nargs="+", default=None, help="only measure filter --limit N's memory, for each N"
    )
    parser.add_argument("--prefix-low-dof", type=int, default=2, help="the widened space's smallest DOF (9: 9 only)")
    parser.add_argument("--prefix-space", choices=("paper", "improv"), default="paper", help="--filter-prefix's space")
    arguments = parser.parse_args()
    from modular_robots.execution import single_threaded_blas

    with single_threaded_blas():
        if arguments.filter_prefix:
            for prefix in arguments.filter_prefix:
                print(filter_prefix(prefix, arguments.prefix_low_dof, arguments.prefix_space), flush=True)
        else:
            main(arguments.scenario, arguments.limit)
