"""Mesh obstacle queries: signed distances of capsules to CoBRA's DMU 125P machine (4,334
triangles, placed as in its PTP_2 task), pair by pair and a query's pairs at once, against the
plain reference (one group of every triangle: no culling by groups, each pair on its own).

The capsules are random, in and around the mesh's box (lengths up to 0.6 m, radii 2 to 8 cm,
one in eight a sphere), seeded; a fifth or so of their axes meet the mesh."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from modular_robots.obstacles import MeshObstacle
from modular_robots.obstacles.mesh import _Geometry, _placed

from ._common import table, write

MESH = Path(__file__).resolve().parents[1] / "scenarios" / "cobra" / "assets" / "DMU_125P_compress.stl"
POSITION = (-0.5, 1.95, 1.8)  # PTP_2's, in the robot's base frame
CAPSULES = 320
BATCH = 160  # about a query of 16 nodes of a robot of ten primitives


def capsules(g: _Geometry, count: int, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    mid = rng.uniform(g.box_center - 1.2 * g.box_half, g.box_center + 1.2 * g.box_half, (count, 3))
    axis = rng.normal(size=(count, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    length = rng.uniform(0.0, 0.6, count)
    length[: count // 8] = 0.0
    return mid, axis, length, rng.uniform(0.02, 0.08, count)


def main() -> None:
    grouped = _placed(MeshObstacle(str(MESH), 0.001, POSITION))
    plain = _Geometry(np.stack([grouped.a, grouped.b, grouped.c], axis=1), group_size=len(grouped.a))
    mid, axis, length, radius = capsules(grouped, CAPSULES, seed=0)
    rows = []

    def timed(label: str, geometry: _Geometry, batch: int) -> np.ndarray:
        start = time.perf_counter()
        parts = [
            geometry.signed_distances(*(v[i : i + batch] for v in (mid, axis, length, radius)))
            for i in range(0, CAPSULES, batch)
        ]
        seconds = time.perf_counter() - start
        out = np.concatenate([p[0] for p in parts])
        rows.append(
            {
                "queries": label,
                "pairs": CAPSULES,
                "pairs_a_call": batch,
                "ms_a_pair": 1e3 * seconds / CAPSULES,
                "axes_meeting_mesh": int(np.sum(out < -radius + 1e-12)),
            }
        )
        return out

    reference = timed("plain reference (every triangle)", plain, 1)
    one = timed("grouped, one pair a call", grouped, 1)
    many = timed(f"grouped, {BATCH} pairs a call", grouped, BATCH)
    assert np.allclose(one, reference, atol=1e-12) and np.allclose(many, reference, atol=1e-12)
    extra = {"mesh": MESH.name, "triangles": len(grouped.a), "groups": len(grouped.groups.members)}
    path = write("mesh", rows, extra)
    print(table(rows))
    print(f"-> {path}")


if __name__ == "__main__":
    main()
