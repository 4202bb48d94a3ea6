"""The ``modular-robots`` command: a thin shell over the Python API."""

from __future__ import annotations

import contextlib
import itertools
import json
import sys
import time
import webbrowser
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from ._yamlio import MAX_FILE_BYTES
from .cli_inputs import (
    ExistingPath,
    Number,
    address_option,
    distinct_files,
    engine_option,
    existing_file,
    file_name,
    folder_name,
    jobs_option,
    max_compositions_option,
    user_errors,
)
from .cli_output import (
    SURVIVOR_ROWS,
    LiveLine,
    clearance_text,
    feasibility_json,
    feasibility_table,
    run_table,
    survivor_table,
    written_files,
)
from .cobra import import_cobra
from .composition import Composition, count_compositions, enumerate_compositions
from .exceptions import InfeasibleError, InputError, shorten
from .execution import make_engine
from .feasibility import (
    FeasibilitySettings,
    FeasibilitySummary,
    composition_space,
    estimate_seconds,
    filter_compositions,
)
from .folder import LOCK, atomic_write, check_writable
from .pipeline import optimize_composition, run_scenario, with_execution, with_pruning
from .report import RESULT, WINNER_FILES, export_controller_rate, is_export
from .ros2 import write_ros2_bundle
from .scenario import MAX_ITERATIONS, RULES, TRANSCRIPTIONS, load_scenario, load_scenario_or_catalog
from .search import SEARCHES, SearchSettings, search_scenario
from .timor import import_timor
from .urdf import write_urdf
from .verdicts import VerdictFile, lock_path
from .viewer import VIEWER, write_viewer

__all__ = ["main"]


def _space(scenario, jobs: int, max_compositions: int, limit: int | None = None) -> int:
    """Say how many compositions step B will check and about how long it takes (or refuse)."""
    total = composition_space(scenario.catalog, max_compositions, jobs, limit)
    click.echo(
        f"step A: {total:,} compositions; step B takes about {estimate_seconds(total, jobs):.0f} s on {jobs} core(s)",
        err=True,
    )
    return total


def _execution(scenario, engine: str | None, address: str | None):
    """``scenario`` with the command line's engine and address (:func:`with_execution`)."""
    if engine == "process" and address is not None:
        raise click.BadParameter(
            "--address is a Ray cluster's; use --engine ray, or leave --address out", param_hint="--address"
        )
    return with_execution(scenario, engine, address)


def _on_ray(scenario) -> bool:
    return scenario.execution.engine == "ray"


def _scenario_files(label: str, path: Path, catalog) -> list[tuple[str, Path | None]]:
    """The files a command read for the scenario (or catalogue) ``path``: it and its catalogue."""
    return [(label, path), (f"the catalogue of {label}", Path(catalog.source) if catalog.source else None)]


def _results_files(out: Path) -> list[tuple[str, Path | None]]:
    """The files a run writes (or replaces, or removes) in the results folder ``out``."""
    names = [RESULT, *WINNER_FILES, VIEWER, LOCK]
    with contextlib.suppress(OSError):
        names += sorted(p.name for p in out.iterdir() if is_export(p.name))
    return [("--out", out / name) for name in names]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="modular-robots")
def main() -> None:
    """Find the best assembly of catalogue modules for a task, and how it moves."""


@main.command("enumerate")
@click.argument("source", type=existing_file, metavar="SCENARIO_OR_CATALOG")
@click.option("--count", is_flag=True, help="Print the number of compositions per DOF instead of their names.")
@click.option("--dof", type=int, default=None, help="Only compositions with this many DOF.")
@max_compositions_option
@user_errors
def enumerate_command(source: Path, count: bool, dof: int | None, max_compositions: int) -> None:
    """Step A: list every composition the catalogue's grammar allows, one per line."""
    _, catalog = load_scenario_or_catalog(source)
    counts = count_compositions(catalog, dof)
    if count:
        click.echo("dof  compositions")
        for k, n in counts.items():
            click.echo(f"{k:<4d} {n}")
        click.echo(f"all  {sum(counts.values())}")
        return
    total = sum(counts.values())
    if total > max_compositions:
        raise InputError(
            f"the catalogue {shorten(catalog.name)} allows {total:,} compositions"
            f"{f' of {dof} DOF' if dof is not None else ''}: too many to list. Count them (--count), choose "
            f"a DOF (--dof) or raise the limit of {max_compositions:,} (--max-compositions)"
        )
    for composition in enumerate_compositions(catalog, dof):
        click.echo(composition.name)


@main.command("urdf")
@click.argument("composition")
@click.option(
    "--scenario",
    "source",
    type=existing_file,
    required=True,
    help="Scenario (payload from its task) or catalogue file.",
)
@click.option(
    "--payload",
    type=Number(0.0, 1e6),
    default=None,
    help="Payload [kg]; default: the scenario's, or 0 for a catalogue.",
)
@click.option("-o", "--output", type=str, callback=file_name("URDF"), required=True, help="URDF file to write.")
@user_errors
def urdf_command(composition: str, source: Path, payload: float | None, output: Path) -> None:
    """Write the URDF of COMPOSITION (e.g. B-J1-L2-E1), payload at tool0."""
    if "+" in composition:
        raise click.BadParameter(
            f"{shorten(composition)}: a '+clear' or '+fastest' suffix names a candidate of `optimize`; "
            "a URDF is of a composition",
            param_hint="COMPOSITION",
        )
    scenario, catalog = load_scenario_or_catalog(source)
    distinct_files([("-o", output)], _scenario_files("--scenario", source, catalog))
    if payload is None:
        payload = scenario.task.payload if scenario else 0.0
    chain = Composition.from_name(composition, catalog)
    write_urdf(output, chain, catalog, payload)
    click.echo(f"wrote {output} ({chain.dof} joints, payload {payload:g} kg)")


@main.command("import-timor")
@click.argument("modules_json", type=existing_file, metavar="MODULES_JSON")
@click.option(
    "--overrides",
    type=existing_file,
    default=None,
    help="YAML of decisions: name, description, grammar, modules to remove, inertia and limit overrides.",
)
@click.option("-o", "--output", type=str, callback=file_name("catalogue"), required=True, help="Catalogue to write.")
@user_errors
def import_timor_command(modules_json: Path, overrides: Path | None, output: Path) -> None:
    """Convert a Timor module database (modules.json) to a general catalogue YAML."""
    distinct_files([("-o", output)], [("MODULES_JSON", modules_json), ("--overrides", overrides)])
    result = import_timor(modules_json, overrides)
    result.write(output)
    for line in result.overrides:
        click.echo(f"override: {line}")
    for line in result.collision:
        click.echo(f"collision: {line}")
    click.echo(f"wrote {output} ({len(result.data['modules'])} modules)")


@main.command("import-cobra")
@click.argument("task_json", type=existing_file, metavar="TASK_JSON")
@click.option(
    "--catalog",
    type=existing_file,
    required=True,
    help="Catalogue the scenario uses (its path is written relative to the scenario).",
)
@click.option(
    "-o",
    "--output",
    type=str,
    callback=file_name("scenario"),
    required=True,
    help="Scenario to write (its meshes beside it, in meshes/).",
)
@click.option(
    "--cost",
    default="cyc",
    show_default=True,
    help="CoBRA cost descriptor: cyc, mechEnergy, mass, numJ, or weighted, e.g. cyc_2,mass_0.1.",
)
@click.option(
    "--payload", type=click.FloatRange(min=0.0), default=0.0, show_default=True, help="Payload at the tool [kg]."
)
@click.option(
    "--max-time",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    help="Longest motion [s] (needed for mechEnergy alone).",
)
@user_errors
def import_cobra_command(
    task_json: Path, catalog: Path, output: Path, cost: str, payload: float, max_time: float | None
) -> None:
    """Convert a CoBRA task (JSON) to a scenario YAML for a catalogue."""
    distinct_files([("-o", output)], [("TASK_JSON", task_json), ("--catalog", catalog)])
    imported = import_cobra(task_json, catalog, output, cost, payload, max_time)
    try:  # it reads back (every check of the reader), or is taken back
        scenario = imported.write(output, load_scenario)
    except InputError as exc:
        raise InputError(f"{task_json}: not imported, the scenario it gives is refused ({exc})") from None
    assert scenario is not None
    goals = len(scenario.task.goals) + 1
    click.echo(
        f"wrote {output} ({goals} goals, {len(scenario.task.obstacles)} obstacles, {len(imported.meshes)} meshes)"
    )


@main.command("filter")
@click.argument("scenario_path", type=existing_file, metavar="SCENARIO")
@jobs_option
@engine_option
@address_option
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=1000),
    default=FeasibilitySettings.seeds,
    show_default=True,
    help="IK start configurations per target.",
)
@click.option(
    "--out",
    "out",
    type=str,
    callback=file_name("JSON"),
    default=None,
    help=(
        "Write the verdict summary and the survivors with their boundary configurations as JSON "
        "(holds every survivor in memory; --verdicts streams)."
    ),
)
@click.option(
    "--verdicts",
    type=str,
    callback=file_name("JSON Lines"),
    default=None,
    help="Write every verdict to this file as it comes (one JSON line per composition, flushed); if the "
    "file holds this run's verdicts already (an interrupted filter), resume after them. Any other file is "
    "refused, untouched; one filter writes a file at a time.",
)
@click.option(
    "--limit",
    type=click.IntRange(min=1),
    default=None,
    help="Check only the first LIMIT compositions of the space (a streamed prefix).",
)
@max_compositions_option
@user_errors
def filter_command(
    scenario_path: Path,
    jobs: int,
    engine: str | None,
    address: str | None,
    seeds: int,
    out: Path | None,
    verdicts: Path | None,
    limit: int | None,
    max_compositions: int,
) -> None:
    """Step B: which compositions can hold the start and the goal (reach, IK, torque, collision)."""
    scenario = _execution(load_scenario(scenario_path), engine, address)
    distinct_files(
        [("--out", out), ("--verdicts", verdicts), ("the lock of --verdicts", verdicts and lock_path(verdicts))],
        _scenario_files("SCENARIO", scenario_path, scenario.catalog),
    )
    settings = FeasibilitySettings(seeds=seeds)
    for path in (out, verdicts):
        if path is not None:
            check_writable(path.parent)
    runner = make_engine(jobs, scenario.execution)
    try:
        total = _space(scenario, runner.jobs, max_compositions, limit)
        # --out lists every survivor; otherwise the table's best are all a stream of millions keeps
        summary = FeasibilitySummary(keep=None if out is not None else SURVIVOR_ROWS)
        start = time.perf_counter()
        compositions = itertools.islice(enumerate_compositions(scenario.catalog), total)
        with (
            VerdictFile(verdicts, scenario, settings) if verdicts else contextlib.nullcontext() as file,
            click.progressbar(
                length=total, label=f"step B on {total} compositions", file=sys.stderr, show_pos=True
            ) as bar,
        ):
            for verdict in file.recorded(compositions) if file else ():
                summary.add(verdict)
                bar.update(1)
            resumed = summary.checked
            for verdict in filter_compositions(scenario, compositions, engine=runner, settings=settings):
                if file:
                    file.write(verdict)
                summary.add(verdict)
                bar.update(1)
        jobs = runner.jobs
    finally:
        runner.close()
    wall = time.perf_counter() - start
    click.echo(feasibility_table(summary))
    click.echo(
        f"{summary.feasible} of {summary.checked} compositions are feasible "
        f"({wall:.1f} s wall, {jobs} worker(s)"
        + (f"; {resumed} verdict(s) read back from {verdicts}" if resumed else "")
        + ")"
    )
    if summary.feasible:
        click.echo(survivor_table(summary, SURVIVOR_ROWS))
    if out is not None:
        atomic_write(out, json.dumps(feasibility_json(scenario, settings, summary, wall, jobs), indent=1) + "\n")
        click.echo(f"wrote {out}")
    if not summary.feasible:
        raise InfeasibleError(summary.diagnosis())


@main.command("optimize")
@click.argument("composition")
@click.option("--scenario", "scenario_path", type=existing_file, required=True, help="Scenario file.")
@click.option(
    "--out",
    "out",
    type=str,
    required=True,
    callback=folder_name,
    help="Results folder (created if missing).",
)
@click.option(
    "--transcription", type=click.Choice(TRANSCRIPTIONS), default=None, help="Override the scenario's transcription."
)
@click.option(
    "--max-iterations",
    type=click.IntRange(min=1, max=MAX_ITERATIONS),
    default=None,
    help="Override the scenario's iteration limit per solve (a solve stopped there goes on once more).",
)
@user_errors
def optimize_command(
    composition: str, scenario_path: Path, out: Path, transcription: str | None, max_iterations: int | None
) -> None:
    """Step C for one COMPOSITION: a verified minimum-cost trajectory and its results folder.

    A composition whose fastest IK pair's straight line passes an obstacle is optimised from its
    fastest clear pair too, one after the other, and the better verified motion wins (as in
    run); NAME+clear or NAME+fastest optimises from that pair only.
    """
    scenario = load_scenario(scenario_path)
    distinct_files(
        _results_files(out),
        _scenario_files("--scenario", scenario_path, scenario.catalog),
        "a results folder apart from the scenario and its catalogue",
    )
    overrides: dict[str, Any] = {
        k: v for k, v in (("transcription", transcription), ("max_iterations", max_iterations)) if v
    }
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, **overrides))
    with LiveLine() as live:

        def progress(name, it):
            if it.warm_up:
                live.show(f"{name}: iteration {it.iteration}  solving the moves one at a time (bound {it.cost:.4g})")
                return
            live.show(
                f"{name}: iteration {it.iteration}  {scenario.task.cost} {it.cost:.4g}  "
                f"tf {it.tf:.3f} s  violation {it.constraint_violation:.1e}"
            )

        run = optimize_composition(scenario, composition, out, on_iterate=progress)
    result = run.winner
    for other in run.candidates:
        if other is not result:
            click.echo(
                f"{other.name}: {other.status}, cost {other.cost:.4g}, {other.iterations} iterations, "
                f"{other.seconds:.2f} s",
                err=True,
            )
    v = result.verification
    assert v is not None  # the winner verified (optimize_composition raises otherwise)
    click.echo(
        f"{result.name}: tf = {result.tf:.4f} s, cost {result.cost:.4g}, {result.iterations} iterations, "
        f"{result.seconds:.2f} s, {result.substeps} sub-steps per interval"
    )
    click.echo(
        f"verified: terminal error {v.terminal_error * 1000:.3f} mm, {clearance_text(v.min_clearance)}, "
        f"velocity {v.velocity_ratio:.3f} x limit, torque {v.torque_ratio:.3f} x limit"
    )
    click.echo(f"wrote {written_files(out)}")


@main.command("run")
@click.argument("scenario_path", type=existing_file, metavar="SCENARIO")
@click.option(
    "--catalog",
    type=existing_file,
    default=None,
    help="With a CoBRA task (SCENARIO a .json file): the catalogue to solve it with; the task is imported "
    "as import-cobra does (cost cyc, no payload) into RESULTS/cobra/.",
)
@click.option(
    "--out",
    "out",
    type=str,
    default=None,
    show_default="results/<scenario name>",
    callback=folder_name,
    help="Results folder (created if missing).",
)
@click.option("--rule", type=click.Choice(RULES), default=None, help="Override the scenario's pruning rule.")
@click.option(
    "--threshold",
    type=Number(0.0, 1e6, positive=True, hint="; to never prune, use --rule none"),
    default=None,
    help="Override the ratio rule's threshold.",
)
@click.option(
    "--search",
    type=click.Choice(SEARCHES),
    default="all",
    show_default=True,
    help="all: step B on every composition, then step C (the paper's); best-first: bounds first, step B "
    "only where a bound leaves a chance, resumable, with a certificate (docs/search.md).",
)
@click.option(
    "--budget",
    type=Number(0.0, 1e9, positive=True),
    default=None,
    help="With --search best-first: end after this many seconds with the best verified robot and its gap "
    "(run again into the same folder to go on).",
)
@jobs_option
@engine_option
@address_option
@max_compositions_option
@user_errors
def run_command(
    scenario_path: Path,
    catalog: Path | None,
    out: Path | None,
    rule: str | None,
    threshold: float | None,
    search: str,
    budget: float | None,
    jobs: int,
    engine: str | None,
    address: str | None,
    max_compositions: int,
) -> None:
    """Steps A to E: the best composition for SCENARIO (a scenario YAML, or a CoBRA task JSON with
    --catalog), its trajectory and a results folder."""
    if budget is not None and search != "best-first":
        raise click.BadParameter("a budget ends a best-first search; add --search best-first", param_hint="--budget")
    if _is_cobra_task(scenario_path):
        if catalog is None:
            raise click.BadParameter(
                f"{scenario_path} is a CoBRA task (JSON): name the catalogue to solve it with", param_hint="--catalog"
            )
        out = out or Path("results") / scenario_path.stem
        scenario_path = _imported_cobra(scenario_path, catalog, out)
    elif catalog is not None:
        raise click.BadParameter(
            "a scenario names its own catalogue; --catalog goes with a CoBRA task (a JSON file with header and goals)",
            param_hint="--catalog",
        )
    scenario = _execution(with_pruning(load_scenario(scenario_path), rule, threshold), engine, address)
    if threshold is not None and scenario.pruning.rule == "none":
        click.echo(f"warning: --threshold {threshold:g} has no effect: the rule none never prunes", err=True)
    out = out or Path("results") / scenario.name
    distinct_files(
        _results_files(out),
        _scenario_files("SCENARIO", scenario_path, scenario.catalog),
        "a results folder apart from the scenario and its catalogue",
    )
    if search == "best-first":
        _search(scenario, out, jobs, budget)
        return
    _space(scenario, make_engine(jobs, scenario.execution).jobs, max_compositions)
    click.echo(
        f"{scenario.name}: rule {scenario.pruning.rule}"
        + (
            f" (threshold {scenario.pruning.threshold:g} from iteration {scenario.pruning.start_iteration})"
            if scenario.pruning.rule == "ratio"
            else ""
        )
        + (f"; on Ray at {scenario.execution.address or 'an instance of its own'}" if _on_ray(scenario) else "")
        + f"; results in {out}",
        err=True,
    )
    total = sum(count_compositions(scenario.catalog).values())
    with LiveLine() as live:
        step_b = {}
        started = time.monotonic()

        def progress(stage, f):
            if stage == "feasibility":
                step_b.update(f)
                if f["checked"] % 50 == 0:
                    live.show(
                        f"steps A+B: {f['checked']} compositions checked, {f['feasible']} feasible"
                        + _step_b_left(f["checked"], total, time.monotonic() - started)
                    )
            else:
                if step_b:  # step B's final count, before step C's lines
                    live.show(f"steps A+B: {step_b['checked']} compositions checked, {step_b['feasible']} feasible")
                    live.settle()
                    step_b.clear()
                best = "-" if f["best_optimal"] is None else f"{f['best_optimal']:.4g}"
                reference = "-" if f["best_cost"] is None else f"{f['best_cost']:.4g}"
                live.show(
                    f"steps C+D: iteration {f['round']}, {f['alive']} of {f['total']} alive, best verified "
                    f"cost {best}, best trusted cost {reference}"
                )

        result = run_scenario(scenario, out, jobs, on_progress=progress, max_compositions=max_compositions)
    click.echo(run_table(result, scenario))
    click.echo(f"wrote {written_files(out)}")


def _is_cobra_task(path: Path) -> bool:
    """Whether ``path`` is a CoBRA task: a ``.json`` file whose object has a ``header`` and
    ``goals`` (a scenario written as JSON has neither)."""
    if path.suffix.lower() != ".json":
        return False
    try:
        with open(path, encoding="utf-8") as file:
            document = json.loads(file.read(MAX_FILE_BYTES + 1))
    except (OSError, ValueError):
        return False
    return isinstance(document, dict) and "header" in document and "goals" in document


def _imported_cobra(task: Path, catalog: Path, out: Path) -> Path:
    """The scenario of the CoBRA ``task`` for ``catalog``, written (with its meshes) into the
    results folder's ``cobra/`` (kept with the results it led to; a run again rewrites it)."""
    distinct_files([("--out", out)], [("SCENARIO", task), ("--catalog", catalog)])
    target = out / "cobra" / f"{task.stem}.yaml"
    import_cobra(task, catalog, target).write(target)
    click.echo(f"imported {task} as {target}", err=True)
    return target


def _step_b_left(checked: int, total: int, seconds: float) -> str:
    """Step B's time still ahead at the rate measured so far (said once it can be measured)."""
    if checked < 100 or seconds < 2.0 or checked >= total:
        return ""
    return f", about {(total - checked) * seconds / checked:.0f} s left at this rate"


def _search(scenario, out: Path, jobs: int, budget: float | None) -> None:
    """``run --search best-first``: the search with its progress on one line, then the summary."""
    space = sum(count_compositions(scenario.catalog).values())
    click.echo(
        f"{scenario.name}: best-first search of {space:,} compositions, rule {scenario.pruning.rule}"
        + (f", budget {budget:g} s" if budget is not None else "")
        + f"; results in {out}",
        err=True,
    )
    last: dict = {}
    with LiveLine() as live:

        def progress(stage, f):
            if stage == "pass":  # listing and bounding the space, before (or between) the steps
                live.show(
                    f"search: pass {f['pass']} over the space, {f['bounded']:,} of {f['space']:,} compositions "
                    f"bounded, about {f['eta']:.0f} s left"
                )
                return
            last.update(f)
            best = "-" if f["best"] is None else f"{f['best']:.4g}"
            lowest = "-" if f["lowest_bound"] is None else f"{f['lowest_bound']:.4g}"
            batch, round_ = f["running"]["candidates"], f["running"]["round"]
            live.show(
                f"search: {f['checked']:,} of {f['space']:,} compositions settled, {f['candidates']} candidates "
                f"optimised"
                + (f" ({batch} in step C, iteration {round_})" if batch else "")
                + f", best verified {best}, smallest bound left {lowest}{_eta(f)}"
            )

        result = search_scenario(scenario, out, jobs, SearchSettings(budget=budget), on_progress=progress)
    click.echo(run_table(result, scenario, last))
    if again := last.get("cut_again"):
        click.echo(
            f"warning: the budget stopped {len(again)} candidate(s) no further than a run before did "
            f"({shorten(again[0])}{', ...' if len(again) > 1 else ''}): it starts over each time (stopped before "
            "its first iterate, or its checkpoint lost); raise --budget",
            err=True,
        )
    click.echo(f"wrote {written_files(out)}")


def _eta(figures: dict) -> str:
    seconds = figures.get("eta")
    return "" if seconds is None else f", about {seconds:.0f} s of step B left at this rate"


@main.command("export")
@click.argument("results", type=ExistingPath(folder=True), metavar="RESULTS_DIR")
@click.option("--rate", type=Number(1.0, 1e5), default=1000.0, show_default=True, help="Controller rate [Hz].")
@click.option(
    "--ros2",
    "ros2_folder",
    type=click.Path(path_type=Path, file_okay=False),
    default=None,
    help="Write a ROS 2 package to this folder instead (URDF with ros2_control, controllers, goal, launch).",
)
@click.option(
    "--goal-rate",
    type=Number(0.1, 1e4),
    default=100.0,
    show_default=True,
    help="Points per second of the ROS 2 goal's trajectory [Hz].",
)
@user_errors
def export_command(results: Path, rate: float, ros2_folder: Path | None, goal_rate: float) -> None:
    """Resample the winner of RESULTS_DIR at a controller rate: a CSV under the zero-order-hold
    contract and a ROS JointTrajectory JSON; with --ros2, a ROS 2 package that plays it."""
    if ros2_folder is not None:
        bundle = write_ros2_bundle(results, ros2_folder, rate, goal_rate)
        if bundle.goal_rate < goal_rate:
            click.echo(
                f"the goal holds {bundle.goal_rate:.3g} points per second, not {goal_rate:g}: more would not fit "
                "one command-line argument of ros2 action send_goal"
            )
        click.echo(f"wrote the ROS 2 package {bundle.package} to {bundle.folder} (its README.md says how to play it)")
        return
    files = export_controller_rate(results, rate)
    click.echo(f"wrote {files['csv']} and {files['json']}")


@main.command("view")
@click.argument("results", type=ExistingPath(folder=True), metavar="RESULTS_DIR")
@click.option("--open", "open_page", is_flag=True, help="Open the page in the default browser.")
@user_errors
def view_command(results: Path, open_page: bool) -> None:
    """Write RESULTS_DIR/winner.html (the winner moving around the obstacles, offline, one file)."""
    path = results / write_viewer(results)
    click.echo(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    if open_page and not webbrowser.open(path.resolve().as_uri()):  # (False: no browser found, or it did not start)
        raise click.ClickException(f"could not open a browser here; open {path} yourself")
