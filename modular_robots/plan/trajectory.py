"""A plan as a robot consumes it: rows under the *acceleration contract* (SPEC §7), and their exact
resampling at a controller rate. Pure array code: the solver that makes a plan is
:mod:`modular_robots.ocp`, whose :func:`~modular_robots.ocp.trajectory.sample_trajectory` samples
a solution into a :class:`Trajectory`.

**The acceleration contract.** On ``[t_i, t_{i+1})`` the joint acceleration is ``qdd_i``,
constant, so each row follows exactly from the one before
(``q_{i+1} = q_i + qd_i h + qdd_i h^2 / 2``, ``qd_{i+1} = qd_i + qdd_i h``), and ``tau_i`` is the
inverse dynamics at ``(q_i, qd_i, qdd_i)`` with the drive's armature and friction: the torque the
drive must deliver at that instant. Where the acceleration jumps, a row carries the value that starts there;
the last row, at ``tf``, the robot at rest (``qdd = 0``, the holding torque).

Because the rows define the motion exactly, :meth:`Trajectory.at` evaluates the plan at any time;
:func:`controller_rate` uses it for the *zero-order-hold contract* of a controller-rate file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..robot import RobotModel

__all__ = ["Trajectory", "controller_rate", "held_torques", "joint_trajectory", "MAX_ROWS", "CONTRACT_TOLERANCE"]

#: The most rows :func:`controller_rate` makes (1000 s of plan at 1 kHz): each row is an inverse
#: dynamics call and ~0.5 kB of CSV, so more would take minutes, gigabytes and a controller no use.
MAX_ROWS = 1_000_000
#: How far a row may be from the one before under the acceleration contract, relative to the
#: terms of the step: the rows are chained exactly, so only rounding separates them.
CONTRACT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Trajectory:
    """A plan sampled under the acceleration contract (module docstring).

    ``t`` (K,) [s]; joint positions ``q``, velocities ``qd``, accelerations ``qdd`` and torques
    ``tau`` (K, nv) [rad, m; /s; /s^2; N m, N]; ``tool`` (K, 3) the tool position [m] in the base
    frame. ``velocity_limit`` and ``effort_limit`` (nv,) are the robot's limits, ``velocity_bound``
    and ``effort_bound`` the ones the plan was optimised within (the limits times the scenario's
    margins); all four are for plots and reports.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    tool: np.ndarray
    velocity_limit: np.ndarray | None = None
    effort_limit: np.ndarray | None = None
    velocity_bound: np.ndarray | None = None
    effort_bound: np.ndarray | None = None

    @property
    def nv(self) -> int:
        return self.q.shape[1]

    def header(self, accelerations: bool = True) -> list[str]:
        """``t,q1..qn,qd1..qdn[,qdd1..qddn],tau1..taun,x,y,z``."""
        groups = ("q", "qd", "qdd", "tau") if accelerations else ("q", "qd", "tau")
        return ["t", *self.header_names(self.nv, groups), "x", "y", "z"]

    def table(self, accelerations: bool = True) -> np.ndarray:
        columns = [self.t, self.q, self.qd, self.qdd, self.tau, self.tool]
        return np.column_stack(columns if accelerations else columns[:3] + columns[4:])

    def write_csv(self, path, accelerations: bool = True) -> None:
        """Write the rows as CSV (SPEC §7's ``trajectory.csv``), every number to full precision.
        Without ``accelerations`` the file has no ``qdd`` columns and follows the
        zero-order-hold contract instead (see :func:`controller_rate`)."""
        np.savetxt(
            path,
            self.table(accelerations),
            delimiter=",",
            header=",".join(self.header(accelerations)),
            comments="",
            fmt="%.17g",
        )

    @classmethod
    def read_csv(cls, path) -> Trajectory:
        """Read a file written by :meth:`write_csv` with its ``qdd`` columns (the acceleration
        contract).

        Raises
        ------
        ValueError
            Naming the file, the row and the column, for a header other than
            ``t,q1..qn,qd1..qdn,qdd1..qddn,tau1..taun,x,y,z``, a cell that is not a finite number,
            fewer than two rows, times that do not start at 0 and increase, or a row that does not
            follow from the one before under the acceleration contract (an edited file).
        """
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
        header = lines[0].strip().split(",") if lines else []
        nv = (len(header) - 4) // 4
        if nv < 1 or header != ["t", *Trajectory.header_names(nv), "x", "y", "z"]:
            raise ValueError(
                f"{path}:1: expected the header t,q1..qn,qd1..qdn,qdd1..qddn,tau1..taun,x,y,z, "
                f"got {','.join(header)[:200]!r}"
            )
        rows = []
        for number, line in enumerate(lines[1:], start=2):
            cells = line.split(",")
            if len(cells) != len(header):
                raise ValueError(f"{path}:{number}: expected {len(header)} values, got {len(cells)}")
            row = []
            for name, cell in zip(header, cells):
                try:
                    value = float(cell)
                except ValueError:
                    value = math.nan
                if not math.isfinite(value):
                    raise ValueError(f"{path}:{number}: column {name}: expected a finite number, got {cell[:40]!r}")
                row.append(value)
            rows.append(row)
        if len(rows) < 2:
            raise ValueError(f"{path}: expected at least 2 rows (t = 0 and t = tf), got {len(rows)}")
        table = np.array(rows)
        steps = np.diff(table[:, 0])
        if table[0, 0] != 0.0 or not np.all(steps > 0.0):
            first = 2 if table[0, 0] != 0.0 else int(np.argmax(steps <= 0.0)) + 3
            raise ValueError(f"{path}:{first}: column t: expected times from 0 that increase row by row")
        q, qd, qdd, tau = (table[:, 1 + k * nv : 1 + (k + 1) * nv] for k in range(4))
        _check_contract(path, table[:, 0], q, qd, qdd)
        return cls(table[:, 0], q, qd, qdd, tau, table[:, -3:])

    @staticmethod
    def header_names(nv: int, groups=("q", "qd", "qdd", "tau")) -> list[str]:
        return [f"{g}{i}" for g in groups for i in range(1, nv + 1)]

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, qd, qdd)`` of the plan at ``times`` [s], exactly, from the contract: the row at or
        before each time and its constant acceleration (right-hand values at the rows)."""
        times = np.clip(np.asarray(times, dtype=float), self.t[0], self.t[-1])
        i = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.t) - 1)
        s = (times - self.t[i])[:, None]
        qdd = self.qdd[i]
        return self.q[i] + self.qd[i] * s + 0.5 * qdd * s * s, self.qd[i] + qdd * s, qdd


def _check_contract(path, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
    """Raise ``ValueError`` naming the first row of the file ``path`` whose ``q`` or ``qd`` do not
    follow from the row before under the acceleration contract (beyond rounding)."""
    h = np.diff(t)[:, None]
    steps = (
        ("q", q[:-1] + qd[:-1] * h + 0.5 * qdd[:-1] * h * h, q[1:], abs(qd[:-1] * h) + abs(0.5 * qdd[:-1] * h * h)),
        ("qd", qd[:-1] + qdd[:-1] * h, qd[1:], abs(qdd[:-1] * h)),
    )
    for group, expected, got, step in steps:
        bad = np.abs(got - expected) > CONTRACT_TOLERANCE * (1.0 + np.abs(got) + np.abs(expected) + step)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(
                f"{path}:{i + 3}: column {group}{j + 1}: expected {expected[i, j]:.10g} (the row before under the "
                f"acceleration contract), got {got[i, j]:.10g}"
            )


def joint_trajectory(trajectory: Trajectory, joint_names: list[str]) -> dict:
    """``trajectory`` shaped like ROS ``trajectory_msgs/JointTrajectory`` (as a JSON-ready dict):
    ``header`` (a zero stamp: start on receipt; frame ``base_link``), ``joint_names`` and
    ``points`` with ``positions``, ``velocities``, ``accelerations``, ``effort`` and
    ``time_from_start`` as ``{sec, nanosec}``."""
    points = []
    for i, t in enumerate(trajectory.t):
        nanoseconds = round(float(t) * 1e9)
        points.append(
            {
                "positions": trajectory.q[i].tolist(),
                "velocities": trajectory.qd[i].tolist(),
                "accelerations": trajectory.qdd[i].tolist(),
                "effort": trajectory.tau[i].tolist(),
                "time_from_start": {"sec": nanoseconds // 1_000_000_000, "nanosec": nanoseconds % 1_000_000_000},
            }
        )
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "base_link"}
    return {"header": header, "joint_names": list(joint_names), "points": points}


def controller_rate(trajectory: Trajectory, robot: RobotModel, rate: float) -> Trajectory:
    """The plan at a controller's rate [Hz]: rows every ``1 / rate`` s from 0 to ``tf`` (and one at
    ``tf``), positions, velocities and accelerations exact (:meth:`Trajectory.at`).

    Its torques follow the *zero-order-hold contract* (SPEC §7): ``tau_i``, held from ``t_i`` to
    ``t_{i+1}``, drives the robot from row ``i`` to row ``i + 1``. It is the mean over that step of
    the plan's own inverse dynamics (:func:`held_torques`), so that a torque held across an instant
    where the plan's acceleration jumps, or where friction changes with the speed (from rest, or
    at a reversal), still lands on the next row's velocity. ``qdd`` holds the plan's own
    acceleration at each row; the last row's ``tau`` holds the robot at rest.
    """
    if not math.isfinite(rate) or rate <= 0.0:
        raise ValueError(f"rate: expected a positive number of rows per second, got {rate}")
    tf = float(trajectory.t[-1])
    if tf * rate + 2 > MAX_ROWS:
        raise ValueError(
            f"rate: {rate:g} Hz over the plan's {tf:g} s makes {tf * rate + 1:.3g} rows; expected at most "
            f"{MAX_ROWS:,} (a lower rate)"
        )
    count = math.floor(tf * rate + 1e-9)
    t = np.arange(count + 1) / rate
    if t[-1] < tf - 1e-12:
        t = np.append(t, tf)
    q, qd, qdd = trajectory.at(t)
    q = _onto_limits(q, robot.lower, robot.upper)
    tau = np.vstack([held_torques(trajectory, robot, t), robot.rnea(q[-1], qd[-1], np.zeros(robot.nv))])
    tool = np.array([robot.tool_position(x) for x in q])
    return Trajectory(
        t,
        q,
        qd,
        qdd,
        tau,
        tool,
        trajectory.velocity_limit,
        trajectory.effort_limit,
        trajectory.velocity_bound,
        trajectory.effort_bound,
    )


#: Gauss-Legendre points per piece of constant acceleration in :func:`held_torques`.
HOLD_POINTS = 4


def held_torques(trajectory: Trajectory, robot: RobotModel, t: np.ndarray) -> np.ndarray:
    """``(K - 1, nv)``: for each step ``[t_i, t_{i+1}]`` of the times ``t`` (K, increasing, within
    the plan), the mean of the plan's inverse dynamics over it [N m | N], the torque that, held
    constant, changes the robot's momentum as the plan does.

    Each step is cut at the plan's own rows (where its acceleration jumps) and every piece
    integrated by :data:`HOLD_POINTS`-point Gauss-Legendre quadrature. The inverse dynamics at the
    step's start with its mean acceleration (what this replaced) is the first term of that mean:
    with Coulomb friction it missed the friction a start from rest meets within the step (row 0 of
    improv-pick at 100 Hz held 16.4 N m where 23.2 N m reach the next row).
    """
    cuts = np.union1d(t, trajectory.t[(trajectory.t > t[0]) & (trajectory.t < t[-1])])
    x, w = np.polynomial.legendre.leggauss(HOLD_POINTS)
    a, b = cuts[:-1, None], cuts[1:, None]
    points = (a + (b - a) * (x + 1.0) / 2.0).ravel()
    q, qd, qdd = trajectory.at(points)
    weighted = robot.rnea(q, qd, qdd).reshape(len(a), HOLD_POINTS, -1) * (w / 2.0)[None, :, None]
    integrals = weighted.sum(axis=1) * (b - a)  # each piece's integral [N m s]
    starts = np.searchsorted(cuts, t[:-1])
    return np.add.reduceat(integrals, starts, axis=0) / np.diff(t)[:, None]


def _onto_limits(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``q`` with a position beyond a joint limit by rounding alone (at most 1e-12 of the limit's
    size, or 1e-12) put on the limit: a plan that rests on a limit is resampled a few ulps past
    it (1e-16 m on a prismatic joint), and a controller may refuse a point beyond the URDF's
    limits. A larger excess is left as it is, for verification to report."""
    slack = 1e-12 * np.maximum(1.0, np.maximum(np.abs(lower), np.abs(upper)))
    below = (q < lower) & (q >= lower - slack)
    above = (q > upper) & (q <= upper + slack)
    return np.where(below, lower, np.where(above, upper, q))
