"""Import a Timor module database (``modules.json``) as a general catalogue YAML.

Timor (TUM, MIT licence) keeps modules as JSON: bodies with inertials about the centre of mass
(Timor builds ``pinocchio.Inertia(mass, r_com, inertia)``, i.e. the inertia is read about the
centre of mass, and so does this importer), joints with ``poseParent``/``poseChild``, limits,
gear ratio, motor inertia and friction, and connectors with a pose, type, size and gender.

What the importer decides, it says: module ids are the modules' ``header.name`` when every name
is a distinct identifier (IMPROV: ``PB21``, ``L1``...), else their ``header.ID`` (geometric
primitives: ``J2``, ``l_45``...). Collision geometry becomes spheres and capsules that contain
it (a sphere stays; a cylinder, box or convex mesh piece gets the smallest capsule, over its
three principal axes and a grid of segment ends, that contains its corners or hull vertices),
and the volume ratio primitives/shape is written in the module's ``notes``. Data that need a
decision (a non-physical inertia, an infinite limit) are refused unless an override file gives
them; every override applied is named in the output's ``notes``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial import ConvexHull

from .exceptions import CatalogError
from .modules import _physical_inertia
from .urdf_assembly import rpy_from_matrix

__all__ = ["import_timor", "TimorImport", "rpy_from_matrix", "fit_capsule", "shape_points"]

#: Default grammar: Timor's ``Science2019`` defaults (0 to 6 joints, up to 3 links between joints).
DEFAULT_GRAMMAR = {"dof": [0, 6], "links_between_joints": [0, 3]}
#: Grid of segment-end positions tried per axis when fitting a capsule.
_GRID = 41


@dataclass(frozen=True)
class TimorImport:
    """The converted catalogue (``data``, ready for YAML) and what was done: one line per
    override applied (``overrides``) and per body's collision conversion (``collision``)."""

    data: dict
    overrides: tuple[str, ...]
    collision: tuple[str, ...]

    def yaml(self) -> str:
        header = "# Converted from a Timor module database by `modular-robots import-timor`; do not edit by hand.\n"
        return header + yaml.safe_dump(self.data, sort_keys=False, width=120)


# -- poses ------------------------------------------------------------------------------------
def _pose(matrix) -> dict:
    m = np.asarray(matrix, dtype=float)
    if m.shape != (4, 4) or not np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-9):
        raise CatalogError(f"expected a 4 x 4 homogeneous transform with a rotation, got {matrix}")
    return {"xyz": [float(x) for x in m[:3, 3]], "rpy": [float(x) for x in rpy_from_matrix(m[:3, :3])]}


def _posed(pose: np.ndarray | None, position: np.ndarray, z_axis: np.ndarray) -> dict:
    """The pose (in the body frame) of a primitive at ``position`` with axis ``z_axis``, both
    given in the frame ``pose`` (a geometry's pose in the body frame)."""
    base = np.eye(4) if pose is None else pose
    z = z_axis / np.linalg.norm(z_axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    local = np.eye(4)
    local[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    local[:3, 3] = position
    return _pose(base @ local)


# -- collision shapes ---------------------------------------------------------------------------
def shape_points(geometry: dict, folder: Path) -> list[np.ndarray]:
    """Points whose convex hull is each convex piece of a Timor geometry (its own frame): the
    corners of a box, two rims of 64 points for a cylinder, a mesh's pieces' vertices."""
    kind, p = geometry["type"], geometry.get("parameters", {})
    if kind == "box":
        half = np.array([p["x"], p["y"], p["z"]], dtype=float) / 2
        return [np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half]
    if kind == "cylinder":
        angle = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        rim = np.column_stack([p["r"] * np.cos(angle), p["r"] * np.sin(angle)])
        return [np.vstack([np.column_stack([rim, np.full(64, s * p["z"] / 2)]) for s in (-1, 1)])]
    if kind == "mesh":
        path = folder / p["file"]
        if not path.is_file():
            raise CatalogError(f"{path}: collision mesh not found (the module database's folder must hold it)")
        scale = np.asarray(p.get("scale", [1.0, 1.0, 1.0]), dtype=float)
        return [piece * scale for piece in _wrl_pieces(path)]
    raise CatalogError(f"collision geometry of type {kind!r}: expected box, cylinder, sphere or mesh")


def _wrl_pieces(path: Path) -> list[np.ndarray]:
    """The vertex lists of a VRML file's ``point [...]`` blocks (one per convex piece)."""
    text = path.read_text("utf-8", errors="replace")
    pieces = []
    for block in re.findall(r"point\s*\[([^\]]*)\]", text):
        numbers = [float(x) for x in re.findall(r"[-+0-9.eE]+", block)]
        pieces.append(np.array(numbers, dtype=float).reshape(-1, 3))
    if not pieces:
        raise CatalogError(f"{path}: no 'point [ ... ]' vertex list found (expected a VRML convex decomposition)")
    return pieces


def fit_capsule(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The smallest capsule found that contains ``points`` (so their convex hull): its centre,
    axis, radius and length (0: a sphere). Tries the three principal axes through the centroid
    and a grid of segment ends along each."""
    centre = points.mean(axis=0)
    _, _, axes = np.linalg.svd(points - centre)
    best: tuple[float, np.ndarray, np.ndarray, float, float] | None = None
    for axis in axes:
        t = (points - centre) @ axis
        radial = np.linalg.norm(points - centre - np.outer(t, axis), axis=1)
        lo, hi = t.min(), t.max()
        grid = np.linspace(lo, hi, _GRID)
        for i, a in enumerate(grid):
            for b in grid[i:]:
                beyond = np.maximum(np.maximum(a - t, t - b), 0.0)
                radius = float(np.sqrt(radial**2 + beyond**2).max()) * (1 + 1e-12) + 1e-12
                volume = math.pi * radius**2 * (b - a) + 4 / 3 * math.pi * radius**3
                if best is None or volume < best[0]:
                    best = (volume, centre + (a + b) / 2 * axis, axis, radius, float(b - a))
    assert best is not None  # three axes, each with a grid of at least one segment
    return best[1], best[2], best[3], best[4]


def _shape_volume(geometry: dict, pieces: list[np.ndarray]) -> float:
    kind, p = geometry["type"], geometry.get("parameters", {})
    if kind == "sphere":
        return 4 / 3 * math.pi * p["r"] ** 3
    if kind == "cylinder":
        return math.pi * p["r"] ** 2 * p["z"]
    if kind == "box":
        return p["x"] * p["y"] * p["z"]
    return float(sum(ConvexHull(piece).volume for piece in pieces))


def _collision(body: dict, folder: Path) -> tuple[list[dict], str]:
    shapes, shape_volume, prim_volume, kinds = [], 0.0, 0.0, []
    for geometry in body.get("collision", []):
        pose = np.asarray(geometry.get("pose", np.eye(4)), dtype=float)
        kinds.append(geometry["type"])
        if geometry["type"] == "sphere":
            r = float(geometry["parameters"]["r"])
            shapes.append({"shape": "sphere", "radius": r, "pose": _pose(pose)})
            shape_volume += 4 / 3 * math.pi * r**3
            prim_volume += 4 / 3 * math.pi * r**3
            continue
        pieces = shape_points(geometry, folder)
        shape_volume += _shape_volume(geometry, pieces)
        for piece in pieces:
            centre, axis, radius, length = fit_capsule(piece)
            prim_volume += math.pi * radius**2 * length + 4 / 3 * math.pi * radius**3
            shape: dict[str, object] = {"shape": "capsule" if length > 1e-9 else "sphere", "radius": radius}
            if length > 1e-9:
                shape["length"] = length
            shape["pose"] = _posed(pose, centre, axis)
            shapes.append(shape)
    note = ""
    if shapes:
        note = (
            f"body {body['ID']}: {'+'.join(kinds)} -> {len(shapes)} primitive(s), volume ratio "
            f"{prim_volume / shape_volume:.2f} (primitives / Timor shape)"
        )
    return shapes, note


# -- modules ----------------------------------------------------------------------------------
def _identifier(text: str) -> str:
    return re.sub(r"\W", "_", str(text))


def _inertia(matrix) -> list[float]:
    m = np.asarray(matrix, dtype=float)
    return [float(m[0, 0]), float(m[1, 1]), float(m[2, 2]), float(m[0, 1]), float(m[0, 2]), float(m[1, 2])]


def _connector(c: dict, body: str) -> dict:
    return {
        "id": _identifier(c["ID"]),
        "body": _identifier(body),
        "pose": _pose(c["pose"]),
        "gender": c["gender"],
        "type": c["type"],
        "size": [float(s) for s in c.get("size", [])],
    }


def _limits(joint: dict, where: str, override: dict) -> dict:
    lim = joint.get("limits", {})
    out = {
        "position": [lim.get("positionLower", -math.inf), lim.get("positionUpper", math.inf)],
        "velocity": lim.get("velocity", math.inf),
        "effort": lim.get("peakTorque", math.inf),
    }
    if math.isfinite(lim.get("acceleration", math.inf)):
        out["acceleration"] = lim["acceleration"]
    out.update(override)
    for key, value in out.items():
        values = value if isinstance(value, list) else [value]
        if not all(math.isfinite(float(v)) for v in values):
            raise CatalogError(
                f"{where}.limits.{key}: {values} is not finite; the optimiser needs finite limits: give them in the "
                f"override file (overrides: - {{module: ..., joint: {joint['ID']}, limits: {{{key}: ...}}}})"
            )
    out["position"] = [float(v) for v in out["position"]]
    return {k: (v if isinstance(v, list) else float(v)) for k, v in out.items()}


def _module(m: dict, module_id: str, folder: Path, overrides: dict, applied: list, notes: list, used: set) -> dict:
    bodies, inlet, outlet = [], None, None
    for body in m["bodies"]:
        where = f"module {module_id}, body {body['ID']}"
        inertia = _inertia(body["inertia"])
        if (module_id, body["ID"]) in overrides:
            o = overrides[(module_id, body["ID"])]
            applied.append(f"{where}: inertia {inertia} -> {o['inertia']} ({o['reason']})")
            used.add((module_id, body["ID"]))
            inertia = [float(x) for x in o["inertia"]]
        mass = float(body["mass"])
        if mass > 0 and not _physical_inertia(tuple(inertia)):
            raise CatalogError(
                f"{where}: inertia {inertia} is not physical (a principal moment above the sum of the other two, or "
                "not positive definite); give a corrected one in the override file (overrides: - {module, body, "
                "inertia, reason})"
            )
        shapes, note = _collision(body, folder)
        if note:
            notes.append(note)
        entry = {"id": _identifier(body["ID"]), "mass": mass}
        if mass > 0:
            entry.update(com=[float(x) for x in body["r_com"]], inertia=inertia)
        if shapes:
            entry["collision"] = shapes
        bodies.append(entry)
        for c in body.get("connectors", []):
            if c["gender"] == "f" or c["type"] == "base":
                inlet = _connector(c, body["ID"])
            else:
                outlet = _connector(c, body["ID"])
    if inlet is None or outlet is None:
        raise CatalogError(f"module {module_id}: expected one female (input) and one male (output) connector")
    joints = []
    for j in m.get("joints", []):
        if j["type"] not in ("revolute", "prismatic"):
            raise CatalogError(f"module {module_id}, joint {j['ID']}: type {j['type']!r} is not revolute or prismatic")
        where = f"module {module_id}, joint {j['ID']}"
        override = overrides.get((module_id, j["ID"]), {})
        if override:
            applied.append(f"{where}: limits {override['limits']} ({override['reason']})")
            used.add((module_id, j["ID"]))
        entry = {
            "id": _identifier(j["ID"]),
            "type": j["type"],
            "parent": _identifier(j["parent"]),
            "child": _identifier(j["child"]),
            "limits": _limits(j, where, override.get("limits", {})),
            "parent_pose": _pose(j.get("poseParent", np.eye(4))),
            "child_pose": _pose(j.get("poseChild", np.eye(4))),
            "gear_ratio": float(j.get("gearRatio", 1.0)),
            "motor_inertia": float(j.get("motorInertia", 0.0)),
            "coulomb": float(j.get("frictionCoulomb", 0.0)),
            "viscous": float(j.get("frictionViscous", 0.0)),
        }
        joints.append(entry)
    out: dict[str, object] = {
        "id": module_id,
        "notes": f"Timor module ID {m['header']['ID']}, name {m['header']['name']!r}",
    }
    out.update(bodies=bodies, joints=joints, inlet=inlet, outlet=outlet)
    if not joints:
        del out["joints"]
    return out


def _read_overrides(path: Path | None) -> dict:
    if path is None:
        return {}
    data = yaml.safe_load(Path(path).read_text("utf-8")) or {}
    allowed = {"name", "description", "remove", "grammar", "overrides", "notes"}
    unknown = set(data) - allowed
    if unknown:
        raise CatalogError(f"{path}: unknown key(s) {sorted(unknown)} (expected some of {sorted(allowed)})")
    for i, o in enumerate(data.get("overrides", [])):
        if "reason" not in o or "module" not in o or ("body" in o) == ("joint" in o):
            raise CatalogError(
                f"{path}: overrides[{i}]: expected module, reason and one of body (+inertia) or joint (+limits)"
            )
    return data


def import_timor(modules_json: str | Path, overrides: str | Path | None = None) -> TimorImport:
    """Convert a Timor ``modules.json`` (and an optional override file) to a general catalogue.

    Raises
    ------
    CatalogError
        For data the model cannot take without a decision (naming the module and field).
    """
    path = Path(modules_json)
    try:
        db = json.loads(path.read_text("utf-8"))  # Python's json reads Timor's bare Infinity tokens
    except (OSError, ValueError) as exc:
        raise CatalogError(f"{path}: not a readable JSON module database ({exc})") from None
    modules = db["modules"] if isinstance(db, dict) else db
    extra = _read_overrides(Path(overrides) if overrides else None)
    names = [str(m["header"].get("name", "")) for m in modules]
    use_names = all(n.isidentifier() for n in names) and len(set(names)) == len(names)
    ids = names if use_names else [_identifier(m["header"]["ID"]) for m in modules]
    keyed = {}
    for o in extra.get("overrides", []):
        key = (o["module"], o.get("body", o.get("joint")))
        keyed[key] = o
    removed = set(extra.get("remove", []))
    unknown = removed - set(ids)
    if unknown:
        raise CatalogError(f"{overrides}: remove: unknown module ids {sorted(unknown)} (known: {ids})")
    applied: list[str] = []
    collision: list[str] = []
    used: set = set()
    out_modules = [
        _module(m, i, path.parent, keyed, applied, collision, used) for m, i in zip(modules, ids) if i not in removed
    ]
    missing = [k for k in keyed if k not in used and k[0] not in removed]
    if missing:
        raise CatalogError(f"{overrides}: overrides for {missing} match no body or joint of the database")
    notes = [
        f"Converted from {path.parent.name}/{path.name} (Timor module database, MIT licence; see LICENSE beside it).",
        f"Module ids: Timor's header.{'name' if use_names else 'ID'}.",
        "Inertias are about the centre of mass, as Timor reads them (pinocchio.Inertia(mass, r_com, inertia)).",
    ]
    if removed:
        notes.append(f"Removed: {', '.join(sorted(removed))}.")
    notes += [f"override: {a}" for a in applied] + list(extra.get("notes", [])) + [f"collision: {c}" for c in collision]
    data = {
        "format": "general",
        "name": extra.get("name", path.parent.name.lower()),
        "description": extra.get("description", f"Timor module database {path.parent.name}"),
        "notes": notes,
        "grammar": extra.get("grammar", DEFAULT_GRAMMAR),
        "modules": out_modules,
    }
    return TimorImport(data, tuple(applied), tuple(collision))
