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
and the volume ratio primitives/shape is written in the module's ``notes``. A visual mesh becomes
an STL beside the catalogue (Timor's, or the convex hulls of the collision mesh's pieces where the
database does not hold it; :attr:`TimorImport.meshes`). Data that need a
decision (a non-physical inertia, an infinite limit) are refused unless an override file gives
them; every override applied is named in the output's ``notes``.

Hostile or malformed data are refused in one line naming the file, the module and the field:
every value is type-checked as it is read, and the catalogue written is first read back by the
catalogue's own loader (:func:`~modular_robots.catalog.catalog_from_fields`), so that the importer
never writes a catalogue that the other commands refuse.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial import ConvexHull, QhullError

from ._yamlio import MAX_FILE_BYTES, MAX_MAGNITUDE, Fields, _LineLoader, load_yaml
from .catalog import MAX_ID_LENGTH, catalog_from_fields
from .composition import count_compositions
from .exceptions import CatalogError, shorten
from .folder import atomic_path, atomic_write
from .modules import MAX_MASS, PENDING_MESHES, _physical_inertia, read_assembly_grammar
from .obstacles._stl import StlError, read_stl, stl_bytes
from .urdf_assembly import rpy_from_matrix

__all__ = ["import_timor", "TimorImport", "rpy_from_matrix", "fit_capsule", "shape_points"]

#: Default grammar: Timor's ``Science2019`` defaults (0 to 6 joints, up to 3 links between joints).
DEFAULT_GRAMMAR = {"dof": [0, 6], "links_between_joints": [0, 3]}
#: Grid of segment-end positions tried per axis when fitting a capsule.
_GRID = 41
#: The largest module database or collision mesh read [bytes]: IMPROV's is 51 kB, its meshes 30 kB.
MAX_INPUT_BYTES = 50_000_000
#: A converted catalogue's name when the database's folder has none (``/modules.json``).
_FALLBACK_NAME = "timor"


@dataclass(frozen=True)
class TimorImport:
    """The converted catalogue (``data``, ready for YAML) and what was done: one line per
    override applied (``overrides``) and per body's collision conversion (``collision``)."""

    data: dict
    overrides: tuple[str, ...]
    collision: tuple[str, ...]
    #: The visual meshes as binary STL, by their path relative to the catalogue (``meshes/<db>/``).
    meshes: dict[str, bytes] = field(default_factory=dict)

    def yaml(self) -> str:
        header = "# Converted from a Timor module database by `modular-robots import-timor`; do not edit by hand.\n"
        return header + yaml.safe_dump(self.data, sort_keys=False, width=120)

    def write(self, path: str | Path) -> None:
        """Write the catalogue to ``path``, its meshes first into ``meshes/<db>/`` beside it (a file
        there with the same bytes is left alone; its name holds a hash of its content)."""
        path = Path(path)
        for name, data in self.meshes.items():
            target = path.parent / name
            if not (target.is_file() and target.read_bytes() == data):
                target.parent.mkdir(parents=True, exist_ok=True)
                with atomic_path(target) as tmp:
                    tmp.write_bytes(data)
        atomic_write(path, self.yaml())


class _Meshes:
    """The visual meshes an import collects: binary STL by path relative to the catalogue."""

    def __init__(self, database: Path):
        folder = re.sub(r"[^A-Za-z0-9_-]", "_", database.parent.name) or _FALLBACK_NAME
        self.prefix = f"meshes/{folder}/"
        self.files: dict[str, bytes] = {}

    def add(self, module_id: str, body_id: str, triangles: np.ndarray) -> str:
        data = stl_bytes(triangles, f"modular-robots: {module_id} body {body_id}")
        name = f"{self.prefix}{module_id}_{body_id}-{hashlib.sha256(data).hexdigest()[:10]}.stl"
        self.files[name] = data
        return name


# -- reading JSON values, each error naming where ------------------------------------------------
@contextmanager
def _within(where: str, sep: str = ": ") -> Iterator[None]:
    """Prefix the :class:`CatalogError` raised inside with ``where`` (``module J2``, ``body b``):
    ``module J2, body b: mass: ...``, ``module J1, joint Prismatic.limits.velocity: ...``."""
    try:
        yield
    except CatalogError as exc:
        message = str(exc)
        raise CatalogError(f"{where}{', ' if message.startswith(('body ', 'joint ')) else sep}{message}") from None


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, (int, float)):
        return f"the number {shorten(value)}"
    if isinstance(value, str):
        return f"the string {shorten(value)}"
    if isinstance(value, list):
        return f"a list of {len(value)} item(s)"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _get(obj: Any, key: str, default: Any = ...) -> Any:
    if not isinstance(obj, dict):
        raise CatalogError(f"expected an object with {key!r}, got {_kind(obj)}")
    if key not in obj:
        if default is ...:
            raise CatalogError(f"{key}: missing required key")
        return default
    return obj[key]


def _number(value: Any, key: str, *, minimum: float | None = None, positive: bool = False) -> float:
    """A finite JSON number of magnitude at most 1e9 (within the bounds given)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CatalogError(f"{key}: expected a number, got {_kind(value)}")
    if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:
        raise CatalogError(f"{key}: expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {shorten(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise CatalogError(f"{key}: expected a finite number, got {number}")
    if abs(number) > MAX_MAGNITUDE:
        raise CatalogError(f"{key}: expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {number:g}")
    if minimum is not None and number < minimum:
        raise CatalogError(f"{key}: expected a number >= {minimum:g}, got {number:g}")
    if positive and number <= 0:
        raise CatalogError(f"{key}: expected a number > 0, got {number:g}")
    return number


def _numbers(value: Any, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A nested JSON list of finite numbers of ``shape`` (``(3,)``, ``(3, 3)``, ``(4, 4)``)."""
    wanted = " x ".join(map(str, shape))
    rows = value if len(shape) == 2 else [value]
    width = shape[-1]
    ok = isinstance(value, list) and len(rows) == shape[0] if len(shape) == 2 else isinstance(value, list)
    if not ok or not all(isinstance(r, list) and len(r) == width for r in rows):
        raise CatalogError(f"{key}: expected {wanted} numbers, got {shorten(value)}")
    out = np.array([[_number(x, key) for x in r] for r in rows], dtype=float)
    return out if len(shape) == 2 else out[0]


def _text(value: Any, key: str) -> str:
    """A JSON id or name: a non-empty string (or a whole number, as text)."""
    if isinstance(value, bool) or not isinstance(value, (str, int)) or value == "":
        raise CatalogError(f"{key}: expected a non-empty string, got {_kind(value)}")
    return str(value)


def _list(value: Any, key: str) -> list:
    if not isinstance(value, list):
        raise CatalogError(f"{key}: expected a list, got {_kind(value)}")
    return value


# -- poses ------------------------------------------------------------------------------------
def _pose(matrix, key: str = "pose") -> dict:
    m = _numbers(matrix, key, (4, 4)) if not isinstance(matrix, np.ndarray) else matrix
    rotation = m[:3, :3]
    if (
        not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
        or np.linalg.det(rotation) <= 0
        or not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9)
    ):
        raise CatalogError(
            f"{key}: expected a 4 x 4 homogeneous transform with a rotation (orthonormal, determinant 1, last row "
            f"0 0 0 1), got {shorten(np.asarray(m).tolist(), 200)}"
        )
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
def _dimension(p: Any, key: str) -> float:
    return _number(_get(p, key), f"parameters.{key}", positive=True)


def shape_points(geometry: dict, folder: Path) -> list[np.ndarray]:
    """Points whose convex hull is each convex piece of a Timor geometry (its own frame): the
    corners of a box, two rims of 64 points for a cylinder, a mesh's pieces' vertices.

    Raises
    ------
    CatalogError
        For a malformed geometry, or a mesh outside ``folder`` (the database's folder must hold
        its meshes), unreadable, or whose pieces span no volume.
    """
    kind, p = _get(geometry, "type"), _get(geometry, "parameters", {})
    if kind == "box":
        half = np.array([_dimension(p, "x"), _dimension(p, "y"), _dimension(p, "z")]) / 2
        return [np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half]
    if kind == "cylinder":
        r, z = _dimension(p, "r"), _dimension(p, "z")
        angle = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        rim = np.column_stack([r * np.cos(angle), r * np.sin(angle)])
        return [np.vstack([np.column_stack([rim, np.full(64, s * z / 2)]) for s in (-1, 1)])]
    if kind == "mesh":
        name = _text(_get(p, "file"), "parameters.file")
        path = _mesh_path(folder, name)
        scale = _numbers(_get(p, "scale", [1.0, 1.0, 1.0]), "parameters.scale", (3,))
        if not (scale > 0).all():
            raise CatalogError(f"parameters.scale: expected 3 numbers > 0, got {scale.tolist()}")
        pieces = [piece * scale for piece in _wrl_pieces(path)]
        for i, piece in enumerate(pieces):
            _hull_volume(piece, f"{name}: piece {i + 1}")
        return pieces
    raise CatalogError(f"type: expected box, cylinder, sphere or mesh, got {_kind(kind)}")


def _mesh_path(folder: Path, name: str) -> Path:
    """The mesh file ``name`` of the database in ``folder``, which must hold it."""
    home = folder.resolve()
    path = (folder / name).resolve()
    if not path.is_relative_to(home):
        raise CatalogError(
            f"parameters.file: {shorten(name)} is outside the module database's folder {shorten(str(home))} "
            "(the folder must hold its meshes)"
        )
    if not path.is_file():
        raise CatalogError(
            f"parameters.file: {path}: collision mesh not found (the module database's folder must hold it)"
        )
    if path.stat().st_size > MAX_INPUT_BYTES:
        raise CatalogError(
            f"parameters.file: {path}: more than {MAX_INPUT_BYTES:,} bytes; a convex decomposition is smaller"
        )
    return path


def _wrl_pieces(path: Path) -> list[np.ndarray]:
    """The vertex lists of a VRML file's ``point [...]`` blocks (one per convex piece)."""
    text = path.read_text("utf-8", errors="replace")
    pieces = []
    for i, block in enumerate(re.findall(r"point\s*\[([^\]]*)\]", text)):
        where = f"{path.name}: piece {i + 1}"
        numbers = []
        for token in re.findall(r"[-+0-9.eE]+", block):
            try:
                numbers.append(float(token))
            except ValueError:
                raise CatalogError(f"{where}: expected x y z numbers, got {shorten(token)}") from None
        if len(numbers) % 3:
            raise CatalogError(f"{where}: {len(numbers)} numbers, not x y z per vertex (a multiple of 3)")
        piece = np.array(numbers, dtype=float).reshape(-1, 3)
        if not np.isfinite(piece).all() or np.abs(piece).max(initial=0.0) > MAX_MAGNITUDE:
            raise CatalogError(f"{where}: expected finite vertices of magnitude at most {MAX_MAGNITUDE:g}")
        pieces.append(piece)
    if not pieces:
        raise CatalogError(f"{path}: no 'point [ ... ]' vertex list found (expected a VRML convex decomposition)")
    return pieces


def _hull_volume(points: np.ndarray, where: str) -> float:
    """The volume of the convex hull of ``points``; refused if it has none."""
    if len(points) < 4:
        raise CatalogError(f"{where}: {len(points)} vertices span no volume (expected a convex piece of at least 4)")
    try:
        volume = float(ConvexHull(points).volume)
    except QhullError:
        volume = 0.0
    if not volume > 0:
        raise CatalogError(f"{where}: its {len(points)} vertices span no volume (all in one plane or line)")
    return volume


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
    if kind == "cylinder":
        return math.pi * p["r"] ** 2 * p["z"]
    if kind == "box":
        return p["x"] * p["y"] * p["z"]
    return float(sum(_hull_volume(piece, "") for piece in pieces))


def _collision(body: dict, body_id: str, folder: Path) -> tuple[list[dict], str]:
    shapes, shape_volume, prim_volume, kinds = [], 0.0, 0.0, []
    for i, geometry in enumerate(_list(_get(body, "collision", []), "collision")):
        with _within(f"collision[{i}]"):
            pose = _numbers(_get(geometry, "pose", np.eye(4).tolist()), "pose", (4, 4))
            _pose(pose)
            kind = _get(geometry, "type")
            if kind == "sphere":
                r = _dimension(_get(geometry, "parameters", {}), "r")
                shapes.append({"shape": "sphere", "radius": r, "pose": _pose(pose)})
                shape_volume += 4 / 3 * math.pi * r**3
                prim_volume += 4 / 3 * math.pi * r**3
                kinds.append(kind)
                continue
            pieces = shape_points(geometry, folder)
            kinds.append(kind)
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
            f"body {body_id}: {'+'.join(kinds)} -> {len(shapes)} primitive(s), volume ratio "
            f"{prim_volume / shape_volume:.2f} (primitives / Timor shape)"
        )
    return shapes, note


def _visual_triangles(body: dict, folder: Path) -> list[np.ndarray]:
    """The body's visual meshes as triangles in the body frame [m]: Timor's STL where the
    database's folder holds it, else the convex hulls of the pieces of the body's collision mesh
    (Timor's IMPROV database names visual STL files it does not ship). Primitive visuals are left
    to the collision shapes, which the URDF draws where a body has no mesh."""
    out = []
    for i, geometry in enumerate(_list(_get(body, "visual", []), "visual")):
        with _within(f"visual[{i}]"):
            if _get(geometry, "type") != "mesh":
                continue
            p = _get(geometry, "parameters", {})
            name = _text(_get(p, "file"), "parameters.file")
            pose = _numbers(_get(geometry, "pose", np.eye(4).tolist()), "pose", (4, 4))
            _pose(pose)
            scale = _numbers(_get(p, "scale", [1.0, 1.0, 1.0]), "parameters.scale", (3,))
            if not (scale > 0).all():
                raise CatalogError(f"parameters.scale: expected 3 numbers > 0, got {scale.tolist()}")
            source = (folder / name).resolve()
            if source.is_relative_to(folder.resolve()) and source.is_file():
                try:
                    triangles = read_stl(source)[0] * scale
                except StlError as exc:
                    raise CatalogError(f"parameters.file: {exc}") from None
                out.append(triangles @ pose[:3, :3].T + pose[:3, 3])
                continue
            out += _collision_hulls(body, folder)
    return out


def _collision_hulls(body: dict, folder: Path) -> list[np.ndarray]:
    """The triangles of the convex hull of every piece of the body's collision meshes, posed in
    the body frame, each turned to face outward."""
    out = []
    for geometry in _list(_get(body, "collision", []), "collision"):
        if _get(geometry, "type") != "mesh":
            continue
        pose = _numbers(_get(geometry, "pose", np.eye(4).tolist()), "pose", (4, 4))
        for piece in shape_points(geometry, folder):
            hull = ConvexHull(piece)
            corners = piece[hull.simplices]
            normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            inward = np.einsum("ij,ij->i", normals, hull.equations[:, :3]) < 0
            corners[inward] = corners[inward][:, [0, 2, 1]]
            out.append(corners @ pose[:3, :3].T + pose[:3, 3])
    return out


# -- modules ----------------------------------------------------------------------------------
def _identifier(text: str) -> str:
    return re.sub(r"\W", "_", str(text))


def _distinct(raw: list[str], what: str) -> list[str]:
    """``raw`` as identifiers, refused if two of them are, or become, one."""
    seen: dict[str, str] = {}
    out = []
    for text in raw:
        ident = _identifier(text)
        if ident in seen:
            if seen[ident] == text:
                raise CatalogError(f"{what} {shorten(text)} appears twice: expected distinct ids")
            raise CatalogError(
                f"{what} {shorten(seen[ident])} and {shorten(text)} both become {shorten(ident)}: expected distinct ids"
            )
        seen[ident] = text
        out.append(ident)
    return out


def _ids(items: list, key: str) -> list[str]:
    out = []
    for i, item in enumerate(items):
        with _within(f"{key}[{i}]"):
            out.append(_text(_get(item, "ID"), "ID"))
    return out


def _inertia(matrix) -> list[float]:
    m = _numbers(matrix, "inertia", (3, 3))
    if not np.allclose(m, m.T, rtol=1e-6, atol=1e-12):
        raise CatalogError(f"inertia: expected a symmetric 3 x 3 matrix, got {shorten(m.tolist(), 200)}")
    return [float(m[0, 0]), float(m[1, 1]), float(m[2, 2]), float(m[0, 1]), float(m[0, 2]), float(m[1, 2])]


def _connector(c: dict, body: str) -> dict:
    size = _list(_get(c, "size", []), "size")
    kind = _get(c, "type")
    if not isinstance(kind, str) or not kind:
        raise CatalogError(f"type: expected a non-empty string, got {_kind(kind)}")
    return {
        "id": _identifier(_text(_get(c, "ID"), "ID")),
        "body": body,
        "pose": _pose(_get(c, "pose")),
        "gender": _get(c, "gender"),
        "type": kind,
        "size": [_number(s, "size") for s in size],
    }


def _limits(joint: dict, joint_id: str, override: dict) -> dict:
    lim = _get(joint, "limits", {})
    if not isinstance(lim, dict):
        raise CatalogError(f"limits: expected an object, got {_kind(lim)}")

    def value(key: str, default: float) -> float:
        v = lim.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise CatalogError(f"limits.{key}: expected a number, got {_kind(v)}")
        return _number(v, f"limits.{key}") if isinstance(v, int) else float(v)

    out: dict[str, Any] = {
        "position": [value("positionLower", -math.inf), value("positionUpper", math.inf)],
        "velocity": value("velocity", math.inf),
        "effort": value("peakTorque", math.inf),
    }
    acceleration = value("acceleration", math.inf)
    if math.isfinite(acceleration):
        out["acceleration"] = acceleration
    out.update(override)
    for key, v in out.items():
        values = v if isinstance(v, list) else [v]
        if not all(math.isfinite(float(x)) for x in values):
            raise CatalogError(
                f"limits.{key}: {values} is not finite; the optimiser needs finite limits: give them in the "
                f"override file (overrides: - {{module: ..., joint: {joint_id}, limits: {{{key}: ...}}}})"
            )
    out["position"] = [_number(x, "limits.position") for x in out["position"]]
    return {k: (v if isinstance(v, list) else _number(v, f"limits.{k}")) for k, v in out.items()}


def _body(
    body: dict, module_id: str, folder: Path, overrides: dict, applied: list, notes: list, used: set, meshes: _Meshes
):
    raw_id = _text(_get(body, "ID"), "ID")
    body_id = _identifier(raw_id)
    with _within(f"body {raw_id}"):
        mass = _number(_get(body, "mass"), "mass", minimum=0.0)
        if mass > MAX_MASS:
            raise CatalogError(f"mass: expected a number <= {MAX_MASS:g} kg, got {mass:g}")
        entry: dict[str, object] = {"id": body_id, "mass": mass}
        key = (module_id, raw_id)
        if mass > 0 or key in overrides:
            inertia = _inertia(_get(body, "inertia"))
            if key in overrides:
                o = overrides[key]
                applied.append(
                    f"module {module_id}, body {raw_id}: inertia {inertia} -> {o['inertia']} ({o['reason']})"
                )
                used.add(key)
                inertia = [float(x) for x in o["inertia"]]
            if mass > 0 and not _physical_inertia(tuple(inertia)):
                raise CatalogError(
                    f"inertia {inertia} is not physical (a principal moment above the sum of the other two, or not "
                    "positive definite); give a corrected one in the override file (overrides: - {module, body, "
                    "inertia, reason})"
                )
            if mass > 0:
                entry.update(com=_numbers(_get(body, "r_com"), "r_com", (3,)).tolist(), inertia=inertia)
        shapes, note = _collision(body, raw_id, folder)
        if note:
            notes.append(note)
        if shapes:
            entry["collision"] = shapes
        triangles = _visual_triangles(body, folder)
        if triangles:
            entry["visual"] = [{"mesh": meshes.add(module_id, body_id, np.concatenate(triangles))}]
        connectors = []
        for i, c in enumerate(_list(_get(body, "connectors", []), "connectors")):
            with _within(f"connectors[{i}]"):
                connectors.append(_connector(c, body_id))
    return entry, connectors


def _module(
    m: dict, module_id: str, folder: Path, overrides: dict, applied: list, notes: list, used: set, meshes: _Meshes
) -> dict:
    bodies, connectors = [], []
    raw_bodies = _list(_get(m, "bodies"), "bodies")
    _distinct(_ids(raw_bodies, "bodies"), "body ids")
    for body in raw_bodies:
        entry, found = _body(body, module_id, folder, overrides, applied, notes, used, meshes)
        bodies.append(entry)
        connectors += found
    for c in connectors:
        if c["gender"] not in ("m", "f"):
            raise CatalogError(
                f"body {c['body']}, connector {c['id']}: gender: expected 'f' (input) or 'm' (output), got "
                f"{_kind(c['gender'])}"
            )
    inlets = [c for c in connectors if c["gender"] == "f"]
    outlets = [c for c in connectors if c["gender"] == "m"]
    if len(inlets) != 1 or len(outlets) != 1:
        raise CatalogError(
            f"connectors: expected one female (input) and one male (output) connector (a serial module), got "
            f"{len(inlets)} female and {len(outlets)} male"
        )
    joints = []
    raw_joints = _list(_get(m, "joints", []), "joints")
    _distinct(_ids(raw_joints, "joints"), "joint ids")
    for j in raw_joints:
        joint_id = _text(j["ID"], "ID")
        with _within(f"joint {joint_id}", "."):
            kind = _get(j, "type")
            if kind not in ("revolute", "prismatic"):
                raise CatalogError(f"type: expected revolute or prismatic, got {_kind(kind)}")
            override = overrides.get((module_id, joint_id), {})
            if override:
                applied.append(
                    f"module {module_id}, joint {joint_id}: limits {override['limits']} ({override['reason']})"
                )
                used.add((module_id, joint_id))
            entry = {
                "id": _identifier(joint_id),
                "type": kind,
                "parent": _identifier(_text(_get(j, "parent"), "parent")),
                "child": _identifier(_text(_get(j, "child"), "child")),
                "limits": _limits(j, joint_id, override.get("limits", {})),
                "parent_pose": _pose(_get(j, "poseParent", np.eye(4).tolist()), "poseParent"),
                "child_pose": _pose(_get(j, "poseChild", np.eye(4).tolist()), "poseChild"),
                "gear_ratio": _number(_get(j, "gearRatio", 1.0), "gearRatio"),
                "motor_inertia": _number(_get(j, "motorInertia", 0.0), "motorInertia"),
                "coulomb": _number(_get(j, "frictionCoulomb", 0.0), "frictionCoulomb"),
                "viscous": _number(_get(j, "frictionViscous", 0.0), "frictionViscous"),
            }
        joints.append(entry)
    header = m["header"]
    out: dict[str, object] = {
        "id": module_id,
        "notes": f"Timor module ID {header['ID']}, name {header.get('name', '')!r}",
    }
    out.update(bodies=bodies, joints=joints, inlet=inlets[0], outlet=outlets[0])
    if not joints:
        del out["joints"]
    return out


# -- the override file --------------------------------------------------------------------------
def _plain(value: Any) -> Any:
    """A parsed YAML value as plain dicts and lists (for ``yaml.safe_dump``)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _strings(f: Fields, key: str) -> list[str]:
    value = f.raw(key, [])
    f.check(key, isinstance(value, list) and all(isinstance(v, str) for v in value), "expected a list of strings")
    return list(value)


def _read_overrides(path: Path | None) -> dict:
    """The override file, checked as the catalogue loader checks a file (one line per error,
    naming the line and key)."""
    if path is None:
        return {}
    top = load_yaml(Path(path), CatalogError)
    data: dict[str, Any] = {}
    for key in ("name", "description"):
        if top.has(key):
            data[key] = top.string(key)
    data["remove"] = _strings(top, "remove")
    data["notes"] = _strings(top, "notes")
    if top.has("grammar"):
        grammar = top.mapping("grammar")
        read_assembly_grammar(grammar)  # refused here, at its line, rather than in the catalogue written
        data["grammar"] = _plain(top.raw("grammar"))
    data["overrides"] = []
    for f in top.mappings("overrides", ()):
        o: dict[str, Any] = {"module": f.string("module"), "reason": f.string("reason")}
        f.check("body", f.has("body") != f.has("joint"), "expected one of body (+inertia) or joint (+limits)")
        if f.has("body"):
            o["body"] = f.string("body")
            o["inertia"] = list(f.vector("inertia", 6))
        else:
            o["joint"] = f.string("joint")
            limits = f.mapping("limits")
            given: dict[str, Any] = {}
            if limits.has("position"):
                given["position"] = list(limits.vector("position", 2))
                limits.check(
                    "position",
                    given["position"][0] < given["position"][1],
                    f"expected [lower, upper] with lower < upper, got {given['position']}",
                )
            for key in ("velocity", "effort", "acceleration"):
                if limits.has(key):
                    given[key] = limits.number(key, exclusive_minimum=0.0)
            limits.done()
            o["limits"] = given
        f.done()
        data["overrides"].append(o)
    top.done()
    return data


# -- the database -------------------------------------------------------------------------------
def _read_database(path: Path) -> list:
    try:
        if path.stat().st_size > MAX_INPUT_BYTES:
            raise CatalogError(f"{path}: more than {MAX_INPUT_BYTES:,} bytes; a module database is smaller")
        db = json.loads(path.read_text("utf-8"))  # Python's json reads Timor's bare Infinity tokens
    except RecursionError:
        raise CatalogError(f"{path}: the JSON is nested too deeply to be a module database") from None
    except (OSError, ValueError) as exc:
        reason = shorten(str(exc).replace("\n", " "), 200, quote=False)
        raise CatalogError(f"{path}: not a readable JSON module database ({reason})") from None
    modules = db.get("modules") if isinstance(db, dict) else db
    if not isinstance(modules, list):
        raise CatalogError(
            f"{path}: expected an object with a list 'modules' (or a list of modules), got "
            f"{_kind(db) if not isinstance(db, dict) else 'modules: ' + _kind(modules)}"
        )
    if not modules:
        raise CatalogError(f"{path}: no modules (expected at least a base and an effector)")
    return modules


def _module_ids(path: Path, modules: list) -> tuple[list[str], bool]:
    """Each module's id (``header.name`` if all are distinct identifiers, else ``header.ID``)."""
    raw_ids, names = [], []
    for i, m in enumerate(modules):
        with _within(f"{path}: modules[{i}]"):
            header = _get(m, "header")
            raw_ids.append(_text(_get(header, "ID"), "header.ID"))
            name = _get(header, "name", "")
            names.append(name if isinstance(name, str) else "")
    if all(n.isidentifier() and len(n) <= MAX_ID_LENGTH for n in names) and len(set(names)) == len(names):
        return names, True
    with _within(str(path)):
        ids = _distinct(raw_ids, "modules' header.ID")
    for raw, ident in zip(raw_ids, ids):
        if len(ident) > MAX_ID_LENGTH:
            raise CatalogError(f"{path}: module {shorten(raw)}: header.ID: expected at most {MAX_ID_LENGTH} characters")
    return ids, False


def _check_written(result: TimorImport, path: Path, overrides: Path | None) -> None:
    """Read ``result`` back with the catalogue loader: refuse what it would refuse, naming the
    module and field (the first use of the catalogue would fail there)."""
    text = result.yaml()
    size = len(text.encode("utf-8"))
    if size > MAX_FILE_BYTES:
        raise CatalogError(
            f"{path}: the catalogue would have {size:,} bytes, more than the {MAX_FILE_BYTES:,} a catalogue may have"
        )
    parsed = yaml.load(text, Loader=_LineLoader)  # the loader's own reading (YAML 1.2, line numbers)
    where = Path("<catalogue>")
    pending = PENDING_MESHES.set(frozenset(str((where.parent / name).resolve()) for name in result.meshes))
    try:
        catalog = catalog_from_fields(Fields(parsed, where, "", CatalogError))
    except CatalogError as exc:
        message = re.sub(r"^<catalogue>:\d+: ", "", str(exc))
        match = re.match(r"modules\[(\d+)\]\.?(.*)", message)
        if match:
            module_id = result.data["modules"][int(match[1])]["id"]
            overridden = overrides is not None and any(
                line.startswith(f"module {module_id},") for line in result.overrides
            )
            after = f"; {overrides} overrides this module's values" if overridden else ""
            raise CatalogError(
                f"{path}: module {module_id}: {match[2]} (the catalogue loader refuses it{after})"
            ) from None
        source = overrides if overrides is not None and message.startswith(("grammar", "name", "notes")) else path
        raise CatalogError(f"{source}: {message} (the catalogue loader refuses it)") from None
    finally:
        PENDING_MESHES.reset(pending)
    if not any(count_compositions(catalog).values()):
        low, high = catalog.grammar.dof
        raise CatalogError(
            f"{overrides if overrides is not None else path}: grammar: the catalogue allows no composition of {low} to "
            f"{high} DOF with its {len(catalog.modules)} modules; expected a grammar.dof its joint sequences can make"
        )


def import_timor(modules_json: str | Path, overrides: str | Path | None = None) -> TimorImport:
    """Convert a Timor ``modules.json`` (and an optional override file) to a general catalogue.

    Raises
    ------
    CatalogError
        For malformed data or data the model cannot take without a decision, in one line naming
        the file, the module and the field; and for a catalogue the catalogue loader would refuse.
    """
    path = Path(modules_json)
    overrides_path = Path(overrides) if overrides else None
    modules = _read_database(path)
    extra = _read_overrides(overrides_path)
    ids, use_names = _module_ids(path, modules)
    keyed = {}
    for o in extra.get("overrides", []):
        key = (o["module"], o.get("body", o.get("joint")))
        keyed[key] = o
    removed = set(extra.get("remove", []))
    unknown = removed - set(ids)
    if unknown:
        raise CatalogError(
            f"{overrides}: remove: unknown module ids {shorten(sorted(unknown))} (known: {shorten(ids)})"
        )
    applied: list[str] = []
    collision: list[str] = []
    used: set = set()
    meshes = _Meshes(path)
    out_modules = []
    for m, i in zip(modules, ids):
        if i in removed:
            continue
        with _within(f"{path}: module {i}"):
            try:
                out_modules.append(_module(m, i, path.parent, keyed, applied, collision, used, meshes))
            except CatalogError:
                raise
            except (KeyError, TypeError, ValueError, IndexError, ArithmeticError, np.linalg.LinAlgError) as exc:
                # every field is checked as it is read; this names the module should one escape
                reason = shorten(str(exc).replace("\n", " "), 120, quote=False)
                raise CatalogError(f"malformed data ({type(exc).__name__}: {reason})") from None
    missing = [k for k in keyed if k not in used and k[0] not in removed]
    if missing:
        raise CatalogError(f"{overrides}: overrides for {shorten(missing)} match no body or joint of the database")
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
        "name": extra.get("name", path.parent.name.lower() or _FALLBACK_NAME),
        "description": extra.get("description", f"Timor module database {path.parent.name}"),
        "notes": notes,
        "grammar": extra.get("grammar", DEFAULT_GRAMMAR),
        "modules": out_modules,
    }
    result = TimorImport(data, tuple(applied), tuple(collision), meshes.files)
    _check_written(result, path, overrides_path)
    return result
