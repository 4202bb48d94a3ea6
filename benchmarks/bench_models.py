"""Step A and model building: compositions per second for enumeration, URDF generation and
Pinocchio model construction, on the paper catalogue."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from modular_robots import composition_urdf, enumerate_compositions, load_catalog, robot_model
from modular_robots.robot import RobotModel, _pinocchio_model

from ._common import best_of, table, write

CATALOG = Path(__file__).resolve().parents[1] / "scenarios" / "catalogs" / "paper.yaml"


def main() -> None:
    catalog = load_catalog(CATALOG)
    compositions = list(enumerate_compositions(catalog))
    sample = compositions[::31]
    rows = []
    seconds = best_of(3, lambda: sum(1 for _ in enumerate_compositions(catalog)))
    rows.append(
        {
            "stage": "enumerate (step A)",
            "items": len(compositions),
            "seconds": seconds,
            "per_second": len(compositions) / seconds,
        }
    )
    seconds = best_of(3, lambda: [composition_urdf(c, catalog, 5.0) for c in sample])
    rows.append({"stage": "URDF text", "items": len(sample), "seconds": seconds, "per_second": len(sample) / seconds})

    def build():
        _pinocchio_model.cache_clear()
        for c in sample:
            robot_model(c, catalog, 5.0)

    seconds = best_of(3, build)
    rows.append(
        {
            "stage": "URDF + Pinocchio model",
            "items": len(sample),
            "seconds": seconds,
            "per_second": len(sample) / seconds,
        }
    )
    robots: list[RobotModel] = [robot_model(c, catalog, 5.0) for c in itertools.islice(sample, 50)]
    rng = np.random.default_rng(0)
    qs = [rng.uniform(r.lower, r.upper) for r in robots]
    seconds = best_of(3, lambda: [r.tool_jacobian(q) for r, q in zip(robots, qs)])
    rows.append(
        {"stage": "tool Jacobian", "items": len(robots), "seconds": seconds, "per_second": len(robots) / seconds}
    )
    path = write("models", rows)
    print(table(rows))
    print(f"-> {path}")


if __name__ == "__main__":
    main()
