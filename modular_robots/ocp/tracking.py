"""Closed-loop check of a plan: the computed-torque tracking of
:mod:`modular_robots.plan.tracking`, which needs no solver, re-exported under its old path."""

from __future__ import annotations

from ..plan.tracking import NATURAL_FREQUENCY, RATE, Tracking, track

__all__ = ["Tracking", "track", "NATURAL_FREQUENCY", "RATE"]
