"""Headroom for feedback: each scenario run with the default effort and velocity margins and at the
full limits (no margin): the winner, its time, the share of the limits it uses, and how a 1 kHz
computed-torque controller tracking it on the exported URDF fares (saturated ticks, tool error)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from modular_robots import OptimizerSettings, load_scenario
from modular_robots.pipeline import run_scenario, track_winner

from ._common import table, write

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
NAMES = ("paper-5kg", "low-10kg", "reach-4dof")
DEFAULT = OptimizerSettings()
SETTINGS = {
    f"effort {DEFAULT.effort_margin:g}, velocity {DEFAULT.velocity_margin:g}": (
        DEFAULT.effort_margin,
        DEFAULT.velocity_margin,
    ),
    "full limits": (1.0, 1.0),
}


def main() -> None:
    rows = []
    for name in NAMES:
        scenario = load_scenario(SCENARIOS / f"{name}.yaml")
        for label, (effort, velocity) in SETTINGS.items():
            optimizer = replace(scenario.optimizer, effort_margin=effort, velocity_margin=velocity)
            run = run_scenario(replace(scenario, optimizer=optimizer))
            winner = run.winner
            tracking = track_winner(winner)
            rows.append(
                {
                    "scenario": name,
                    "margins": label,
                    "winner": winner.name,
                    "tf_s": winner.tf,
                    "effort_used": float(abs(winner.trajectory.tau / winner.trajectory.effort_limit).max()),
                    "velocity_used": float(abs(winner.trajectory.qd / winner.trajectory.velocity_limit).max()),
                    "tracking_clipped_share": tracking.clipped_share,
                    "tracking_tool_error_mm": tracking.tool_error * 1e3,
                    "tracking_max_deviation_mm": tracking.max_deviation * 1e3,
                    "tracking_velocity_ratio": tracking.velocity_ratio,
                    "iterations": run.iterations,
                }
            )
            print(table(rows[-1:]), flush=True)
    for row in rows:
        full = next(r for r in rows if r["scenario"] == row["scenario"] and r["margins"] == "full limits")
        row["tf_vs_full_limits"] = row["tf_s"] / full["tf_s"]
    path = write("margins", rows)
    print(table(rows))
    print(f"-> {path}")


if __name__ == "__main__":
    main()
