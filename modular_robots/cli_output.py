"""What the command line prints and writes: its tables, its live status line and ``filter``'s
JSON."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import click

from .costs import COSTS
from .feasibility import TEST_NAMES, FeasibilitySummary, Verdict
from .plan.boundary import BoundaryPair
from .plan.document import RESULT, read_document, result_design

__all__ = [
    "LiveLine",
    "SURVIVOR_ROWS",
    "clearance_text",
    "feasibility_json",
    "feasibility_table",
    "run_table",
    "survivor_table",
    "written_files",
]

#: What the summary says for the clearance when no obstacle is within reach of the robot (or the
#: task has none), where the figure is infinite.
_NO_OBSTACLE = "no obstacle within reach"

#: Survivors ``filter`` prints (the smallest time bounds); without ``--out`` it holds no more.
SURVIVOR_ROWS = 25


def written_files(out: Path) -> str:
    """The files of the results folder ``out``, as its ``result.json`` lists them."""
    winner = read_document(out).winner
    files = winner.files.names() if winner is not None else ()
    return f"{out}/ ({', '.join([RESULT, *files])})"


def run_table(result, scenario, search: dict | None = None) -> str:
    """The summary ``run`` prints: the winner, its verification, the counts and times (with a
    best-first search's last ``search`` figures, how far each composition went)."""
    w = result.winner
    statuses = [c.status for c in result.candidates]
    clear = sum(c.boundary_pair == BoundaryPair.CLEAR for c in result.candidates)
    v = w.verification
    rows = [
        (
            "winner",
            w.composition
            + ("" if w.boundary_pair == BoundaryPair.FASTEST else f" (from its {w.boundary_pair} boundary pair)"),
        ),
        ("tf [s]", f"{w.tf:.4f}"),
        (f"cost ({scenario.task.cost})", f"{w.cost:.4g}" + (f" {unit}" if (unit := scenario.task.cost.unit) else "")),
        *_tie_break_row(result, scenario),
        (
            "verification",
            f"terminal error {v.terminal_error * 1000:.3f} mm, {clearance_text(v.min_clearance)}, "
            f"{w.substeps} sub-steps",
        ),
        (
            ("compositions", f"{result.feasibility.checked} enumerated, {result.feasibility.feasible} feasible")
            if search is None
            else (
                "compositions",
                f"{search['space']:,} in the space: {search['step_b_relaxed']:,} through step B without its "
                f"collision test, {search['step_b']:,} through the whole step B, "
                f"{result.feasibility.feasible:,} feasible",
            )
        ),
        (
            "candidates",
            f"{len(statuses)} optimised ({len({c.composition for c in result.candidates})} compositions, {clear} also "
            "from a clear pair): "
            f"{statuses.count('optimal')} optimal, "
            f"{statuses.count('pruned')} pruned, {statuses.count('failed')} failed"
            + (f", {stopped} stopped before their end" if (stopped := statuses.count("stopped")) else ""),
        ),
        ("optimizer iterations", f"{result.iterations} in {result.rounds} lockstep rounds"),
        *([("certificate", result.certificate.line())] if result.certificate is not None else []),
        *_unconverged_row(result, scenario),
        ("wall time [s]", ", ".join(f"{k} {s:.1f}" for k, s in result.seconds.items())),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {value}" for k, value in rows)


def _tie_break_row(result, scenario) -> list[tuple[str, str]]:
    """With a lexicographic objective: the verified robots within the tie band, and what chose."""
    objective = scenario.task.cost
    if not objective.then:
        return []
    verified = [c for c in result.candidates if c.status == "optimal"]
    best = min(c.cost for c in verified)
    tied = [c for c in verified if c.cost <= objective.limit(best)]  # (equal to 12 digits, as ranked)

    design = result_design(result.winner, scenario)
    values = ", ".join(_with_unit(name, COSTS[name].value(design)) for name in objective.then)  # type: ignore[attr-defined]
    return [
        (
            "tie-break",
            f"{values}; {len(tied)} verified within {objective.within:.3g} of the best cost {best:.4g} "
            f"(of {len(verified)} verified)",
        )
    ]


def _with_unit(name: str, value: float) -> str:
    unit = getattr(COSTS[name], "unit", "")
    return f"{name} {value:.4g}" + (f" {unit}" if unit else "")


def _unconverged_row(result, scenario) -> list[tuple[str, str]]:
    settings = scenario.optimizer
    below = result.unconverged_below_winner(settings.constraint_tolerance, scenario.task.cost.band)
    if not below:
        return []
    best = below[0]
    return [
        (
            "not converged",
            f"{len(below)} failed at the iteration limit feasible at their nodes with a lower cost than "
            + ("the winner's" if scenario.task.cost.band == 1.0 else "the tie band's")
            + f" (best {best.name}, {best.cost:.4g}); unranked; a higher optimizer.max_iterations "
            f"(now {settings.max_iterations}) may let them converge",
        )
    ]


class LiveLine:
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

    def settle(self) -> None:
        """Leave the last line shown (a stage's final figures) and start the next on a new one."""
        if self.tty and self.count:
            click.echo("", err=True)
        elif self.text and self.count % 10 != 1:
            click.echo(self.text, err=True)
        self.count, self.text = 0, ""

    def __exit__(self, *exc):
        self.settle()
        return False


def feasibility_table(summary: FeasibilitySummary) -> str:
    """Step B's cascade: what each test removed, what remained and its CPU seconds."""
    remaining = summary.remaining_after()
    lines = [f"{'test':<20} {'removed':>8} {'remaining':>10} {'cpu s':>8}"]
    for test in TEST_NAMES:
        lines.append(f"{test:<20} {summary.removed[test]:>8} {remaining[test]:>10} {summary.seconds[test]:>8.2f}")
    lines.append(f"{'(model building)':<20} {'':>8} {'':>10} {summary.seconds['model']:>8.2f}")
    return "\n".join(lines)


def survivor_table(summary: FeasibilitySummary, limit: int = SURVIVOR_ROWS) -> str:
    """The ``limit`` survivors with the smallest time bounds, and how many more there are."""
    ranked = sorted(summary.survivors, key=_time_bound)
    lines = [f"{'composition':<34} {'dof':>3} {'time bound s':>12} {'torque ratio':>12} {'clearance m':>11}"]
    for v in ranked[:limit]:
        lines.append(
            f"{v.composition.name:<34} {v.composition.dof:>3} {v.time_bound:>12.3f} "
            f"{v.figures['torque_ratio']:>12.3f} {_clearance_cell(v.figures['clearance']):>11}"
        )
    if summary.feasible > limit:
        lines.append(f"... and {summary.feasible - limit} more (see --out)")
    return "\n".join(lines)


def _time_bound(verdict: Verdict) -> float:
    """A survivor's time bound [s], which every passing verdict has."""
    assert verdict.time_bound is not None  # a survivor passed, and a passing verdict has one
    return verdict.time_bound


def clearance_text(clearance: float) -> str:
    """A verified plan's smallest obstacle clearance [m] as the summaries print it."""
    return f"min clearance {clearance:.4f} m" if math.isfinite(clearance) else _NO_OBSTACLE


def _clearance_cell(clearance: float) -> str:
    return f"{clearance:.3f}" if math.isfinite(clearance) else "-"


def feasibility_json(scenario, settings, summary, wall, jobs) -> dict:
    """``filter --out``'s document: the settings, the counts and every survivor held, by time bound."""
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
