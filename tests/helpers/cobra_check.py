"""A CoBRA solution checked as CoBRA's checker defines its goals and constraints (Timor's
``Goals`` and ``Constraints``), on the document's rows alone: Pinocchio's kinematics of the
robot's URDF, placed at the document's ``basePose``; nothing of the product's solver or
verification. Used by ``tests/test_cobra.py`` and by the goals benchmark on CoBRA's samples."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from modular_robots.robot import robot_from_urdf

#: CoBRA's bound on the tool's spatial velocity at a ``reach`` goal (Timor's default).
REACH_SPEED = 1e-3
#: CoBRA's bound on the L2 distances of ``q``, ``dq`` and ``ddq`` at a ``returnTo`` goal.
RETURN_DISTANCE = 1e-4


def check_solution(task: dict, document: dict, urdf: str, armature=None) -> dict:
    """Assert every goal of ``task`` (a CoBRA task's JSON) and the joint limits on the rows of
    ``document`` (a solution's JSON); return the figures: each pose goal's position error [m] and
    angle [rad], each reach's tool speed, the largest share of a limit."""
    robot = robot_from_urdf(urdf, armature)
    model, data, frame = robot.model, robot.data, robot.tool_frame_id
    traj = document["trajectory"]
    t, q, dq, ddq, tau = (np.array(traj[k], dtype=float) for k in ("t", "q", "dq", "ddq", "tau"))
    step = task["header"].get("timeStepSize", 0.01)
    assert np.all(np.diff(t) > 0), "t must increase"
    assert np.diff(t).max() <= step + 1e-9, f"rows {np.diff(t).max()} s apart, more than the task's {step} s"
    base = pin.SE3(np.array(document["basePose"][0], dtype=float))
    times = traj["goal2time"]
    row = {}
    for goal in task["goals"]:
        hits = np.flatnonzero(np.isclose(t, times[goal["ID"]]))  # CoBRA's own lookup: exactly one row
        assert len(hits) == 1, (goal["ID"], times[goal["ID"]], hits)
        row[goal["ID"]] = int(hits[0])
    figures: dict = {"position_error": {}, "angle": {}, "reach_speed": {}}
    first = task["goals"][0]["ID"]
    for goal in task["goals"]:
        gid, kind, k = goal["ID"], goal["type"].lower(), row[goal["ID"]]
        if kind in ("at", "reach"):
            pin.framesForwardKinematics(model, data, q[k])
            tool = base * data.oMf[frame]
            pose = goal["goalPose"]
            nominal = np.array(pose["nominal"], dtype=float)
            error = float(np.linalg.norm(tool.translation - nominal[:3, 3]))
            angle = float(np.linalg.norm(pin.log3(nominal[:3, :3].T @ tool.rotation)))
            for name, (low, high) in zip(pose["toleranceProjection"], pose["tolerance"]):
                if name == "r_sph":
                    assert low - 1e-12 <= error <= high + 1e-12, (gid, "r_sph", error, high)
                elif name == "Theta_R":
                    assert low - 1e-12 <= angle <= high + 1e-12, (gid, "Theta_R", angle, high)
                else:  # x, y, z in the nominal frame
                    axis = "xyz".index(name)
                    delta = (nominal[:3, :3].T @ (tool.translation - nominal[:3, 3]))[axis]
                    assert low - 1e-12 <= delta <= high + 1e-12, (gid, name, delta)
            figures["position_error"][gid], figures["angle"][gid] = error, angle
        if kind == "reach":
            jacobian = pin.computeFrameJacobian(model, data, q[k], frame, pin.LOCAL_WORLD_ALIGNED)
            speed = float(np.abs(jacobian @ dq[k]).max())
            assert speed <= REACH_SPEED, (gid, "reach speed", speed)
            figures["reach_speed"][gid] = speed
        if kind == "pause":
            start = int(np.flatnonzero(t <= t[k] - goal["duration"] + 1e-9)[-1])
            window = slice(start, k + 1)
            assert not np.any(q[window] != q[start]), (gid, "q moves in the pause")
            assert not dq[window].any() and not ddq[window].any(), (gid, "dq or ddq in the pause")
        if kind == "returnto":
            back = row.get(goal.get("returnToGoal", first), 0) if goal.get("returnToGoal") else 0
            for values in (q, dq, ddq):
                assert np.linalg.norm(values[k] - values[back]) <= RETURN_DISTANCE, (gid, "returnTo")
    order = [times[g["ID"]] for g in task["goals"]]
    for constraint in task.get("constraints", []):
        if constraint.get("type") == "allGoalsFulfilledInOrder":
            listed = [times[i] for i in constraint["order"]]
            assert listed == sorted(listed), ("order", listed)
    assert times[first] == 0.0 and order[-1] <= t[-1] + 1e-9
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    assert np.all(q >= lower - 1e-9) and np.all(q <= upper + 1e-9), "a position limit"
    share = max(float(np.max(np.abs(dq) / model.velocityLimit)), float(np.max(np.abs(tau) / model.effortLimit)))
    assert share <= 1.0 + 1e-3, ("a velocity or torque limit", share)
    assert np.allclose(tau, robot.rnea(q, dq, ddq), atol=1e-9), "tau is not the inverse dynamics of the rows"
    figures["limit_share"] = share
    return figures
