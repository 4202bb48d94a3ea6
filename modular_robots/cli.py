"""The ``modular-robots`` command: a thin shell over the Python API."""

from __future__ import annotations

import contextlib
import errno
import functools
import itertools
import json
import math
import os
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

import click

from .composition import Composition, count_compositions, enumerate_compositions
from .exceptions import InfeasibleError, InputError, ModularRobotsError, Terminated, shorten
from .execution import ENGINES, JOBS_PER_CORE, available_cores, make_engine, max_jobs, terminations_raise
from .feasibility import (
    MAX_COMPOSITIONS,
    TEST_NAMES,
    FeasibilitySettings,
    FeasibilitySummary,
    composition_space,
    estimate_seconds,
    filter_compositions,
)
from .folder import atomic_write, check_writable
from .ocp.candidate import BoundaryPair
from .pipeline import optimize_composition, run_scenario, with_execution, with_pruning
from .report import RESULT, export_controller_rate
from .scenario import MAX_ITERATIONS, RULES, TRANSCRIPTIONS, load_scenario, load_scenario_or_catalog
from .timor import import_timor
from .urdf import write_urdf
from .verdicts import VerdictFile
from .viewer import write_viewer

__all__ = ["main"]


def _user_errors(command):
    """End every failure with a one-line ``Error: …`` and a non-zero exit, never a traceback:
    package errors and failed file operations exit 1, an interruption 130 (Ctrl-C) or 128 + the
    signal's number (``SIGTERM``, ``SIGHUP``, …; the first signal decides, later ones are ignored);
    a reader that closed our output (``| head``) ends the command quietly; anything else is
    reported as unexpected (set ``MODULAR_ROBOTS_DEBUG=1`` for its traceback)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            with terminations_raise(final=True):
                return command(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except BrokenPipeError:
            _reader_gone()
        except ModularRobotsError as exc:
            first, _, details = str(exc).partition("\n")
            if details:  # a diagnosis: its details first, the sentence last
                click.echo(details, err=True)
            raise click.ClickException(first) from None
        except Terminated as exc:
            _fail(str(exc), 128 + exc.signum)
        except KeyboardInterrupt:
            _fail("interrupted by the user", 130)
        except OSError as exc:
            raise click.ClickException(_os_error(exc)) from None
        except Exception as exc:
            if os.environ.get("MODULAR_ROBOTS_DEBUG"):
                raise
            raise click.ClickException(
                f"unexpected {type(exc).__name__}: {shorten(exc, 300, quote=False)} "
                "(please report it with the command and its input files; MODULAR_ROBOTS_DEBUG=1 shows where)"
            ) from None

    return wrapper


def _fail(message: str, code: int) -> None:
    click.echo(f"Error: {message}", err=True)
    sys.exit(code)


def _reader_gone() -> None:
    """Exit as a command killed by ``SIGPIPE`` would (141), without a word: the reader of our
    output has gone (``enumerate | head``). Output still buffered goes nowhere."""
    with contextlib.suppress(OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.exit(128 + signal.SIGPIPE)


def _os_error(exc: OSError) -> str:
    where = f"{shorten(exc.filename, 200, quote=False)}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc}"


class _Number(click.ParamType):
    """A finite number in a range (click's ``FloatRange`` lets ``nan`` through)."""

    name = "number"

    def __init__(self, minimum: float = -1e9, maximum: float = 1e9, *, positive: bool = False, hint: str = ""):
        self.minimum, self.maximum, self.positive, self.hint = minimum, maximum, positive, hint

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"expected a number, got {shorten(value)}", param, ctx)
        if not math.isfinite(number):
            self.fail(f"expected a finite number, got {value}{self.hint}", param, ctx)
        if self.positive and not self.minimum < number <= self.maximum:
            self.fail(f"expected a number in ({self.minimum:g}, {self.maximum:g}], got {number:g}", param, ctx)
        if not self.minimum <= number <= self.maximum:
            self.fail(f"expected a number in [{self.minimum:g}, {self.maximum:g}], got {number:g}", param, ctx)
        return number


#: Linux's limits on a file or folder name (``NAME_MAX``) and on a whole path (``PATH_MAX``, its
#: final NUL included) [bytes].
NAME_MAX, PATH_MAX = 255, 4096
#: Survivors ``filter`` prints (the smallest time bounds); without ``--out`` it holds no more.
SURVIVOR_ROWS = 25


def _path_problem(path: Path) -> str | None:
    """Why ``path`` can be neither opened nor created, or None: a name or the whole path too long,
    a loop of symbolic links. Said before any work, without echoing a huge path."""
    for part in path.parts:
        if len(os.fsencode(part)) > NAME_MAX:
            return f"{shorten(part)}: a file or folder name is at most {NAME_MAX} bytes"
    size = len(os.fsencode(os.path.abspath(path)))
    if size >= PATH_MAX:
        return f"{shorten(str(path), 200)}: a path is at most {PATH_MAX - 1} bytes, this one has {size}"
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"{shorten(str(path), 200)}: a loop of symbolic links"
        if exc.errno == errno.ENAMETOOLONG:
            return f"{shorten(str(path), 200)}: {exc.strerror}"
    return None


def _output_path(text: str, kind: str) -> Path:
    """``text`` as the path of an output (a results folder, a file): checked before any work, so
    that hours of it are never lost to a name that cannot be written. It must be UTF-8 (it is
    written into ``result.json`` and the page), and :func:`_path_problem` must find nothing."""
    if not text.strip():
        raise click.BadParameter(f"expected {kind}, got an empty name")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        code = ord(text[exc.start])
        byte = f"the byte 0x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"the character U+{code:04X}"
        raise click.BadParameter(
            f"{shorten(text, 200)}: expected a name in UTF-8 (it is written into the results), got {byte}"
        ) from None
    problem = _path_problem(Path(text))
    if problem:
        raise click.BadParameter(problem)
    return Path(text)


def _folder_name(ctx, param, text: str | None) -> Path | None:
    """``--out`` of ``run`` and ``optimize``: a usable results folder (:func:`_output_path`)."""
    if text is None:
        return None
    value = _output_path(text, "a folder")
    if value.exists() and not value.is_dir():
        raise click.BadParameter(f"{shorten(value, 200, quote=False)} exists and is not a folder")
    if value.resolve() == Path(value.resolve().anchor):
        raise click.BadParameter("the filesystem's root; expected a results folder")
    return value


def _file_name(kind: str):
    """The callback of an option naming a ``kind`` file to write (:func:`_output_path`); an existing
    folder, device or pipe is refused (renaming a file onto it would replace it)."""

    def check(ctx, param, text: str | None) -> Path | None:
        if text is None:
            return None
        value = _output_path(text, f"a {kind} file name")
        if value.exists() and not value.is_file():
            raise click.BadParameter(
                f"{shorten(value, 200, quote=False)} is not a regular file; expected a {kind} file name"
            )
        return value

    return check


class _ExistingPath(click.ParamType):
    """An existing file (or folder) to read; its problems said in one short line."""

    name = "path"

    def __init__(self, folder: bool = False):
        self.folder = folder

    def convert(self, value, param, ctx):
        if isinstance(value, Path):
            return value
        path = Path(value)
        problem = _path_problem(path)
        if problem:
            self.fail(problem, param, ctx)
        if not path.exists():
            self.fail(f"{shorten(value, 200, quote=False)}: no such {'folder' if self.folder else 'file'}", param, ctx)
        if self.folder and not path.is_dir():
            self.fail(f"{shorten(value, 200, quote=False)} is not a folder", param, ctx)
        if not self.folder and path.is_dir():
            self.fail(f"{shorten(value, 200, quote=False)} is a folder; expected a file", param, ctx)
        return path


class _Jobs(click.ParamType):
    """``--jobs``: 0 (every core) to :func:`~modular_robots.execution.max_jobs`."""

    name = "integer"

    def convert(self, value, param, ctx):
        try:
            jobs = int(value)
        except (TypeError, ValueError):
            self.fail(f"expected a whole number, got {shorten(value)}", param, ctx)
        if not 0 <= jobs <= max_jobs():
            self.fail(
                f"expected 0 (every core) to {max_jobs()} ({JOBS_PER_CORE} per core: more workers only share the "
                f"{available_cores()} core(s) and each needs its own memory), got {shorten(jobs)}",
                param,
                ctx,
            )
        return jobs


_jobs = click.option(
    "--jobs",
    "-j",
    type=_Jobs(),
    default=0,
    show_default="all cores",
    help="Worker processes (1: run in this process).",
)


def _space(scenario, jobs: int, max_compositions: int, limit: int | None = None) -> int:
    """Say how many compositions step B will check and about how long it takes (or refuse)."""
    total = composition_space(scenario.catalog, max_compositions, jobs, limit)
    click.echo(
        f"step A: {total:,} compositions; step B takes about {estimate_seconds(total, jobs):.0f} s on {jobs} core(s)",
        err=True,
    )
    return total


_engine = click.option(
    "--engine",
    type=click.Choice(ENGINES),
    default=None,
    show_default="the scenario's execution.engine, else process",
    help="Where steps B-D run: worker processes on this machine, or a Ray cluster.",
)


def _ray_address(ctx, param, text: str | None) -> str | None:
    if text is not None and (not text.strip() or text != text.strip() or len(text) > 300):
        raise click.BadParameter(f"expected a Ray address (auto, host:port or ray://host:port), got {shorten(text)}")
    return text


_address = click.option(
    "--address",
    type=str,
    default=None,
    callback=_ray_address,
    help="The Ray cluster to run on (auto: the one `ray start --head` started on this machine; host:port); "
    "implies --engine ray. Without it, --engine ray starts a Ray instance of this run's own with --jobs CPUs.",
)


def _execution(scenario, engine: str | None, address: str | None):
    """``scenario`` with the command line's engine and address (:func:`with_execution`)."""
    if engine == "process" and address is not None:
        raise click.BadParameter(
            "--address is a Ray cluster's; use --engine ray, or leave --address out", param_hint="--address"
        )
    return with_execution(scenario, engine, address)


def _on_ray(scenario) -> bool:
    return scenario.execution.engine == "ray"


_max_compositions = click.option(
    "--max-compositions",
    type=click.IntRange(min=1),
    default=MAX_COMPOSITIONS,
    show_default=True,
    help="Refuse a catalogue whose grammar allows more compositions (step B's time grows with them).",
)


_existing_file = _ExistingPath()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="modular-robots")
def main() -> None:
    """Find the best assembly of catalogue modules for a task, and how it moves."""


@main.command("enumerate")
@click.argument("source", type=_existing_file, metavar="SCENARIO_OR_CATALOG")
@click.option("--count", is_flag=True, help="Print the number of compositions per DOF instead of their names.")
@click.option("--dof", type=int, default=None, help="Only compositions with this many DOF.")
@_max_compositions
@_user_errors
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
    type=_existing_file,
    required=True,
    help="Scenario (payload from its task) or catalogue file.",
)
@click.option(
    "--payload",
    type=_Number(0.0, 1e6),
    default=None,
    help="Payload [kg]; default: the scenario's, or 0 for a catalogue.",
)
@click.option("-o", "--output", type=str, callback=_file_name("URDF"), required=True, help="URDF file to write.")
@_user_errors
def urdf_command(composition: str, source: Path, payload: float | None, output: Path) -> None:
    """Write the URDF of COMPOSITION (e.g. B-J1-L2-E1), payload at tool0."""
    if "+" in composition:
        raise click.BadParameter(
            f"{shorten(composition)}: a '+clear' or '+fastest' suffix names a candidate of `optimize`; "
            "a URDF is of a composition",
            param_hint="COMPOSITION",
        )
    scenario, catalog = load_scenario_or_catalog(source)
    if payload is None:
        payload = scenario.task.payload if scenario else 0.0
    chain = Composition.from_name(composition, catalog)
    write_urdf(output, chain, catalog, payload)
    click.echo(f"wrote {output} ({chain.dof} joints, payload {payload:g} kg)")


@main.command("import-timor")
@click.argument("modules_json", type=_existing_file, metavar="MODULES_JSON")
@click.option(
    "--overrides",
    type=_existing_file,
    default=None,
    help="YAML of decisions: name, description, grammar, modules to remove, inertia and limit overrides.",
)
@click.option("-o", "--output", type=str, callback=_file_name("catalogue"), required=True, help="Catalogue to write.")
@_user_errors
def import_timor_command(modules_json: Path, overrides: Path | None, output: Path) -> None:
    """Convert a Timor module database (modules.json) to a general catalogue YAML."""
    result = import_timor(modules_json, overrides)
    atomic_write(output, result.yaml())
    for line in result.overrides:
        click.echo(f"override: {line}")
    for line in result.collision:
        click.echo(f"collision: {line}")
    click.echo(f"wrote {output} ({len(result.data['modules'])} modules)")


@main.command("filter")
@click.argument("scenario_path", type=_existing_file, metavar="SCENARIO")
@_jobs
@_engine
@_address
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
    callback=_file_name("JSON"),
    default=None,
    help=(
        "Write the verdict summary and the survivors with their boundary configurations as JSON "
        "(holds every survivor in memory; --verdicts streams)."
    ),
)
@click.option(
    "--verdicts",
    type=str,
    callback=_file_name("JSON Lines"),
    default=None,
    help="Write every verdict to this file as it comes (one JSON line per composition, flushed); if the "
    "file holds verdicts already (an interrupted filter), resume after them.",
)
@click.option(
    "--limit",
    type=click.IntRange(min=1),
    default=None,
    help="Check only the first LIMIT compositions of the space (a streamed prefix).",
)
@_max_compositions
@_user_errors
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
    click.echo(_feasibility_table(summary))
    click.echo(
        f"{summary.feasible} of {summary.checked} compositions are feasible "
        f"({wall:.1f} s wall, {jobs} worker(s)"
        + (f"; {resumed} verdict(s) read back from {verdicts}" if resumed else "")
        + ")"
    )
    if summary.feasible:
        click.echo(_survivor_table(summary))
    if out is not None:
        atomic_write(out, json.dumps(_feasibility_json(scenario, settings, summary, wall, jobs), indent=1) + "\n")
        click.echo(f"wrote {out}")
    if not summary.feasible:
        raise InfeasibleError(summary.diagnosis())


@main.command("optimize")
@click.argument("composition")
@click.option("--scenario", "scenario_path", type=_existing_file, required=True, help="Scenario file.")
@click.option(
    "--out",
    "out",
    type=str,
    required=True,
    callback=_folder_name,
    help="Results folder (created if missing).",
)
@click.option(
    "--transcription", type=click.Choice(TRANSCRIPTIONS), default=None, help="Override the scenario's transcription."
)
@click.option(
    "--max-iterations",
    type=click.IntRange(min=1, max=MAX_ITERATIONS),
    default=None,
    help="Override the scenario's iteration limit.",
)
@_user_errors
def optimize_command(
    composition: str, scenario_path: Path, out: Path, transcription: str | None, max_iterations: int | None
) -> None:
    """Step C for one COMPOSITION: a verified minimum-cost trajectory and its results folder.

    A composition whose fastest IK pair's straight line passes an obstacle is optimised from its
    fastest clear pair too, one after the other, and the better verified motion wins (as in
    ``run``); NAME+clear or NAME+fastest optimises from that pair only.
    """
    scenario = load_scenario(scenario_path)
    overrides = {k: v for k, v in (("transcription", transcription), ("max_iterations", max_iterations)) if v}
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, **overrides))
    with _LiveLine() as live:

        def progress(name, it):
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
    click.echo(
        f"{result.name}: tf = {result.tf:.4f} s, cost {result.cost:.4g}, {result.iterations} iterations, "
        f"{result.seconds:.2f} s, {result.substeps} sub-steps per interval"
    )
    click.echo(
        f"verified: terminal error {v.terminal_error * 1000:.3f} mm, min clearance {v.min_clearance:.4f} m, "
        f"velocity {v.velocity_ratio:.3f} x limit, torque {v.torque_ratio:.3f} x limit"
    )
    click.echo(f"wrote {_written(out)}")


@main.command("run")
@click.argument("scenario_path", type=_existing_file, metavar="SCENARIO")
@click.option(
    "--out",
    "out",
    type=str,
    default=None,
    show_default="results/<scenario name>",
    callback=_folder_name,
    help="Results folder (created if missing).",
)
@click.option("--rule", type=click.Choice(RULES), default=None, help="Override the scenario's pruning rule.")
@click.option(
    "--threshold",
    type=_Number(0.0, 1e6, positive=True, hint="; to never prune, use --rule none"),
    default=None,
    help="Override the ratio rule's threshold.",
)
@_jobs
@_engine
@_address
@_max_compositions
@_user_errors
def run_command(
    scenario_path: Path,
    out: Path | None,
    rule: str | None,
    threshold: float | None,
    jobs: int,
    engine: str | None,
    address: str | None,
    max_compositions: int,
) -> None:
    """Steps A to E: the best composition for SCENARIO, its trajectory and a results folder."""
    scenario = _execution(with_pruning(load_scenario(scenario_path), rule, threshold), engine, address)
    if threshold is not None and scenario.pruning.rule == "none":
        click.echo(f"warning: --threshold {threshold:g} has no effect: the rule none never prunes", err=True)
    out = out or Path("results") / scenario.name
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
    with _LiveLine() as live:

        def progress(stage, f):
            if stage == "feasibility":
                if f["checked"] % 50 == 0:
                    live.show(f"steps A+B: {f['checked']} compositions checked, {f['feasible']} feasible")
            else:
                best = "-" if f["best_optimal"] is None else f"{f['best_optimal']:.4g}"
                reference = "-" if f["best_cost"] is None else f"{f['best_cost']:.4g}"
                live.show(
                    f"steps C+D: iteration {f['round']}, {f['alive']} of {f['total']} alive, best verified "
                    f"cost {best}, pruning reference {reference}"
                )

        result = run_scenario(scenario, out, jobs, on_progress=progress, max_compositions=max_compositions)
    click.echo(_run_table(result, scenario))
    click.echo(f"wrote {_written(out)}")


@main.command("export")
@click.argument("results", type=_ExistingPath(folder=True), metavar="RESULTS_DIR")
@click.option("--rate", type=_Number(1.0, 1e5), default=1000.0, show_default=True, help="Controller rate [Hz].")
@_user_errors
def export_command(results: Path, rate: float) -> None:
    """Resample the winner of RESULTS_DIR at a controller rate: a CSV under the zero-order-hold
    contract and a ROS JointTrajectory JSON."""
    files = export_controller_rate(results, rate)
    click.echo(f"wrote {files['csv']} and {files['json']}")


@main.command("view")
@click.argument("results", type=_ExistingPath(folder=True), metavar="RESULTS_DIR")
@click.option("--open", "open_page", is_flag=True, help="Open the page in the default browser.")
@_user_errors
def view_command(results: Path, open_page: bool) -> None:
    """Write RESULTS_DIR/winner.html (the winner moving around the obstacles, offline, one file)."""
    path = results / write_viewer(results)
    click.echo(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    if open_page:
        code = click.launch(str(path))
        if code != 0:
            raise click.ClickException(
                f"could not open a browser (the system's opener exited with {code}); open {path} yourself"
            )


def _written(out: Path) -> str:
    """The files of the results folder ``out``, as its ``result.json`` lists them."""
    document = json.loads((out / RESULT).read_text())
    files = (document.get("winner") or {}).get("files", {})
    return f"{out}/ ({', '.join([RESULT, *files.values()])})"


def _run_table(result, scenario) -> str:
    w = result.winner
    statuses = [c.status for c in result.candidates]
    v = w.verification
    rows = [
        (
            "winner",
            w.composition
            + ("" if w.boundary_pair == BoundaryPair.FASTEST else f" (from its {w.boundary_pair} boundary pair)"),
        ),
        ("tf [s]", f"{w.tf:.4f}"),
        (f"cost ({scenario.task.cost})", f"{w.cost:.4g}"),
        (
            "verification",
            f"terminal error {v.terminal_error * 1000:.3f} mm, min clearance "
            f"{v.min_clearance:.4f} m, {w.substeps} sub-steps",
        ),
        ("compositions", f"{result.feasibility.checked} enumerated, {result.feasibility.feasible} feasible"),
        (
            "candidates",
            f"{len(statuses)} optimised ({result.feasibility.feasible} compositions, "
            f"{sum(c.boundary_pair == BoundaryPair.CLEAR for c in result.candidates)} also from a clear pair): "
            f"{statuses.count('optimal')} optimal, "
            f"{statuses.count('pruned')} pruned, {statuses.count('failed')} failed",
        ),
        ("optimizer iterations", f"{result.iterations} in {result.rounds} lockstep rounds"),
        ("wall time [s]", ", ".join(f"{k} {s:.1f}" for k, s in result.seconds.items())),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {value}" for k, value in rows)


class _LiveLine:
    """One status line on stderr, rewritten in place on a terminal (every 10th update otherwise)."""

    def __init__(self):
        self.tty = sys.stderr.isatty()
        self.count = 0
        self.text = ""

    def __enter__(self):
        return self

    def show(self, text: str) -> None:
        self.count += 1
        self.text = text
        if self.tty:
            click.echo(f"\r\033[K{text}", nl=False, err=True)
        elif self.count % 10 == 1:
            click.echo(text, err=True)

    def __exit__(self, *exc):
        if self.tty and self.count:
            click.echo("", err=True)
        elif self.text and self.count % 10 != 1:
            click.echo(self.text, err=True)
        return False


def _feasibility_table(summary: FeasibilitySummary) -> str:
    remaining = summary.remaining_after()
    lines = [f"{'test':<20} {'removed':>8} {'remaining':>10} {'cpu s':>8}"]
    for test in TEST_NAMES:
        lines.append(f"{test:<20} {summary.removed[test]:>8} {remaining[test]:>10} {summary.seconds[test]:>8.2f}")
    lines.append(f"{'(model building)':<20} {'':>8} {'':>10} {summary.seconds['model']:>8.2f}")
    return "\n".join(lines)


def _survivor_table(summary: FeasibilitySummary) -> str:
    ranked, limit = sorted(summary.survivors, key=lambda v: v.time_bound), SURVIVOR_ROWS
    lines = [f"{'composition':<34} {'dof':>3} {'time bound s':>12} {'torque ratio':>12} {'clearance m':>11}"]
    for v in ranked[:limit]:
        lines.append(
            f"{v.composition.name:<34} {v.composition.dof:>3} {v.time_bound:>12.3f} "
            f"{v.figures['torque_ratio']:>12.3f} {v.figures['clearance']:>11.3f}"
        )
    if summary.feasible > limit:
        lines.append(f"... and {summary.feasible - limit} more (see --out)")
    return "\n".join(lines)


def _feasibility_json(scenario, settings, summary, wall, jobs) -> dict:
    return {
        "scenario": scenario.name,
        "settings": {
            "seeds": settings.seeds,
            "tolerance": settings.tolerance,
            "max_iterations": settings.max_iterations,
            "jobs": jobs,
        },
        "enumerated": summary.checked,
        "removed": summary.removed,
        "remaining": summary.remaining_after(),
        "cpu_seconds": summary.seconds,
        "wall_seconds": wall,
        "diagnosis": summary.diagnosis(),
        "survivors": [v.to_json() for v in sorted(summary.survivors, key=lambda v: v.time_bound)],
    }
