"""Lower bounds on the distance from segments to a mesh's triangles, and the groups of
neighbouring triangles that let a query bound a few hundred groups before it bounds a triangle
(a two-level bounding-volume hierarchy, in NumPy; every length in metres).

A bound is the larger of two: the gap between the segment's box and a box that holds the
triangles, and the distance from the segment to a centre less a radius that holds them. Both
hold for a group as for one triangle, so a triangle in a group whose bound exceeds a distance
already measured cannot be nearer than it: culling by groups first leaves the same nearest
triangles as culling every triangle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Groups", "group_triangles", "segment_lower_bounds"]


@dataclass(frozen=True)
class Groups:
    """Triangles ``members`` ``(G, S)`` (indices; a short last group repeats its last member)
    and, per group, the box ``low``, ``high`` ``(G, 3)`` and the ball ``centre`` ``(G, 3)``,
    ``reach`` ``(G,)`` that hold them."""

    members: np.ndarray
    low: np.ndarray
    high: np.ndarray
    centre: np.ndarray
    reach: np.ndarray


def group_triangles(triangles: np.ndarray, size: int) -> Groups:
    """Groups of at most ``size`` triangles ``(T, 3, 3)``, split in halves along the longest
    side of their centroids' box until small enough (a median split: neighbours stay together)."""
    centroids = triangles.mean(axis=1)
    groups, pending = [], [np.arange(len(triangles))]
    while pending:
        index = pending.pop()
        if len(index) <= size:
            groups.append(np.pad(index, (0, size - len(index)), mode="edge"))
            continue
        points = centroids[index]
        axis = int(np.argmax(points.max(axis=0) - points.min(axis=0)))
        half = size * -(-len(index) // (2 * size))  # whole groups on the first side
        order = np.argpartition(points[:, axis], half - 1)
        pending += [index[order[:half]], index[order[half:]]]
    members = np.array(groups)
    corners = triangles[members].reshape(len(members), -1, 3)
    low, high = corners.min(axis=1), corners.max(axis=1)
    centre = 0.5 * (low + high)
    reach = np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)
    return Groups(members, low, high, centre, reach)


def segment_lower_bounds(
    start: np.ndarray, direction: np.ndarray, low: np.ndarray, high: np.ndarray, centre: np.ndarray, reach: np.ndarray
) -> np.ndarray:
    """Lower bounds ``(..., N)`` on the distance from segments (``start`` and ``direction``
    ``(..., 3)``; a point where ``direction`` is zero) to what each of ``N`` boxes (``low``,
    ``high``) and balls (``centre``, ``reach``) both hold."""
    end = start + direction
    lo, hi = np.minimum(start, end)[..., None, :], np.maximum(start, end)[..., None, :]
    gap = np.maximum(np.maximum(low - hi, lo - high), 0.0)
    offset = centre - start[..., None, :]
    span = np.einsum("...c,...c->...", direction, direction)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.einsum("...tc,...c->...t", offset, direction) / span, 0.0, 1.0)
    t = np.where(span > 0.0, t, 0.0)
    apart = np.linalg.norm(offset - t[..., None] * direction[..., None, :], axis=-1)
    return np.maximum(np.sqrt(np.einsum("...c,...c->...", gap, gap)), apart - reach)
