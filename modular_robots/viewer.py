"""``winner.html``: the winner moving around the obstacles, in one self-contained page.

The page is written from the results folder alone (``result.json``, ``winner.urdf``,
``trajectory.csv``), so ``modular-robots view RESULTS_DIR`` can rebuild it at any time. The robot
is the URDF's collision geometry (a cylinder in the URDF stands for a capsule) posed by yourdfpy's
forward kinematics along the plan's acceleration contract; three.js (r147, MIT, vendored in
``viewer_assets/``) draws it. Everything the page needs is inlined: it opens from the file system,
offline, and makes no request.
"""

from __future__ import annotations

import html
import io
import json
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any, cast

import numpy as np

from .appearance import KIND_COLOURS, KIND_LABELS, colour_of_rgba
from .costs import Design, Objective, parse_objective
from .exceptions import InputError, shorten
from .execution import signals_deferred
from .folder import ResultsFolder, atomic_write
from .obstacles import obstacle_label
from .obstacles._stl import MAX_VISUAL_TRIANGLES, StlError, read_stl, welded
from .plan.candidate import CandidateStatus
from .plan.document import drawn_task, winner_plan_files
from .plan.records import CandidateRecord, ResultDocument
from .plan.trajectory import Trajectory
from .report import read_winner, winner_robot
from .robot import robot_from_urdf
from .urdf import is_mesh_copy

__all__ = ["VIEWER", "write_viewer", "write_page", "scene_data", "FRAME_RATE", "HEADLESS_CHROMIUM"]

VIEWER = "winner.html"
#: Frames per second of motion stored in the page (the player shows the nearest frame).
FRAME_RATE = 60.0
#: At most this many frames, whatever the motion's length.
MAX_FRAMES = 1200
#: Flags to open the page in headless Chromium (tests, screenshots): as root, WebGL on SwiftShader,
#: and none of Chromium's own network traffic.
HEADLESS_CHROMIUM = (
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)
#: Colours by module kind (first letter of the module id), for the links of the URDF.
#: A link without a coloured ``<visual>`` (a URDF from before they were written).
_UNPAINTED = "#9aa0a6"


def write_viewer(folder: str | Path) -> str:
    """Write ``winner.html`` into the results folder ``folder`` from its files; return its name.
    The folder is locked meanwhile, so a run cannot start into it (:func:`write_page`).

    Raises
    ------
    InputError
        If the folder has no readable winner (:func:`~modular_robots.report.read_winner`,
        :func:`~modular_robots.report.winner_robot`).
    FolderBusyError
        If a run is writing into the folder.
    """
    with ResultsFolder(folder, busy_hint="view it once that run has ended", create=False):
        return write_page(folder)


def write_page(folder: str | Path) -> str:
    """:func:`write_viewer` without taking the folder's lock: for the run that holds it."""
    folder = Path(folder)
    document, urdf, trajectory = read_winner(folder)
    winner_robot(folder, document, urdf, trajectory)
    urdf_path = winner_plan_files(document, folder)[0]
    try:
        scene = scene_data(urdf_path, trajectory, document)
    except (ValueError, RuntimeError, TypeError, KeyError, AttributeError, SyntaxError) as exc:
        raise InputError(f"{urdf_path}: cannot pose the winner ({shorten(exc, 120, quote=False)})") from None
    title = f"{document.winner.candidate if document.winner else ''} — modular-robots"
    atomic_write(folder / VIEWER, page(scene, panel(document), title))
    return VIEWER


def scene_data(urdf_path: Path, trajectory: Trajectory, document: ResultDocument | Mapping[str, Any]) -> dict:
    """What the page draws: per link its shapes and per frame its pose, the tool path, the
    obstacles with the clearance margin, the start and goal. Poses are 4x4 matrices, column-major
    (three.js's order), in the base frame [m]. ``document``: as read, or its JSON (whose task
    and margin may be missing)."""
    text = Path(urdf_path).read_bytes()  # parsed from memory: lxml takes no file name it cannot encode
    joints = robot_from_urdf(text.decode("utf-8")).joint_names
    tf = float(trajectory.t[-1])
    count = int(min(MAX_FRAMES, max(2, np.ceil(tf * FRAME_RATE) + 1)))
    times = np.linspace(0.0, tf, count)
    qs = trajectory.at(times)[0]
    folder = Path(urdf_path).parent
    frames = []
    # trimesh (imported here, not at start-up) swallows BaseException in places: a Ctrl-C or
    # SIGTERM waits for the end of the block instead of being lost to a later, made-up error
    with signals_deferred():
        import yourdfpy

        urdf = yourdfpy.URDF.load(io.BytesIO(text), load_meshes=False)
        painted = any(link.visuals for link in urdf.link_map.values())  # a URDF from before visuals: its shapes
        links = [link for link in urdf.link_map.values() if (link.visuals if painted else link.collisions)]
        for q in qs:
            urdf.update_cfg(dict(zip(joints, q)))
            frames.append([_columns(urdf.get_transform(link.name, urdf.base_link)) for link in links])
    tool = np.column_stack([np.interp(times, trajectory.t, trajectory.tool[:, k]) for k in range(3)])
    task = drawn_task(document)
    return {
        "tf": tf,
        "times": _round(times),
        "links": [
            {
                "name": link.name,
                "color": _colour(link),
                "shapes": _shapes(link.visuals, folder) if painted else _shapes(link.collisions, folder, "capsule"),
            }
            for link in links
        ],
        "frames": frames,
        "tool": _round(tool),
        "obstacles": [
            {
                "center": _round(o.bounding_sphere()[0]),
                "parts": o.page(),
                "shell": o.page(task.clearance_margin) if task.clearance_margin > 0 else [],
            }
            for o in task.obstacles
        ],
        "start": list(task.start) if task.start is not None else None,
        "goal": list(task.goal) if task.goal is not None else None,
        "waypoints": [list(p) for p in task.waypoints],
    }


def _shapes(elements, folder: Path, cylinder: str = "cylinder") -> list[dict]:
    """A link's ``<visual>`` or ``<collision>`` elements in the page's vocabulary: primitives as
    they are (a collision cylinder, which stands for a capsule, as ``cylinder="capsule"``), a mesh
    (one of the copies beside the URDF, :func:`~modular_robots.urdf.localise_meshes`) as its welded
    triangles, scaled."""
    out: list[dict] = []
    for element in elements:
        geometry = element.geometry
        if geometry.cylinder is not None:
            out.append({"type": cylinder, "radius": geometry.cylinder.radius, "length": geometry.cylinder.length})
        elif geometry.sphere is not None:
            out.append({"type": "sphere", "radius": geometry.sphere.radius})
        elif geometry.box is not None:
            out.append({"type": "box", "size": [float(v) for v in geometry.box.size]})
        elif geometry.mesh is not None:
            vertices, faces = welded(_mesh_triangles(folder, geometry.mesh))
            out.append({"type": "mesh", "vertices": _round(vertices), "faces": faces.tolist()})
        else:
            continue
        # yourdfpy leaves the origin None when the URDF gives none (the identity)
        out[-1]["origin"] = _columns(np.eye(4) if element.origin is None else element.origin)
    return out


def _mesh_triangles(folder: Path, mesh) -> np.ndarray:
    """The triangles of a visual mesh of the URDF in ``folder``, scaled: only a copy beside it."""
    name = str(mesh.filename)
    if not is_mesh_copy(name) or (folder / name).is_symlink():
        raise ValueError(f"visual mesh {shorten(name)}: expected one of the mesh_*.stl files beside the URDF")
    try:
        triangles = read_stl(folder / name, MAX_VISUAL_TRIANGLES)[0]
    except StlError as exc:
        raise ValueError(str(exc)) from None
    scale = np.ones(3) if mesh.scale is None else np.broadcast_to(np.asarray(mesh.scale, dtype=float), 3)
    return triangles * scale


def _colour(link) -> str:
    """The colour of the link's first ``<visual>`` material (its module's kind: the URDF says it)."""
    for visual in link.visuals:
        material = visual.material
        if material is not None and material.color is not None and material.color.rgba is not None:
            return colour_of_rgba(material.color.rgba)
    return KIND_COLOURS["payload"] if link.name == "payload" else _UNPAINTED


def _columns(matrix: np.ndarray) -> list[float]:
    return _round(np.asarray(matrix, dtype=float).T.ravel())


def _round(values: np.ndarray) -> list:
    return np.round(np.asarray(values, dtype=float), 5).tolist()


# -- the panel ------------------------------------------------------------------------------------
def panel(document: ResultDocument) -> str:
    """The winner's figures and the candidates' ranking, as HTML."""
    w = document.winner
    if w is None:
        raise ValueError(f"{document.source}: no winner to show")
    e = html.escape
    rows = [
        ("tf", f"{w.tf:.4f} s"),
        (f"cost ({document.settings.cost})", f"{w.cost:.4g}"),
    ]
    approach = w.closest_approach
    if approach:
        rows.append(
            (
                "closest approach",
                f"{approach.clearance * 1000:.1f} mm at t = {approach.t:.3f} s, "
                f"{approach.primitive} to {_obstacle_label(document, approach.obstacle)}",
            )
        )
    if w.verification:
        rows.append(("tool error at tf", f"{_figure(w.verification.terminal_error, 1000, '.3f')} mm"))
    used = w.limits_used
    if used:
        rows.append(("torque use per joint", " ".join(f"{100 * u:.0f}%" for u in used.effort)))
        rows.append(("speed use per joint", " ".join(f"{100 * u:.0f}%" for u in used.velocity)))
    figures = "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in rows)
    ranking = _ranking(document.candidates, w.candidate, document.settings.cost)
    searched = document.settings.extra.get("search") == "best-first" and document.message
    certificate = f"<p class='sub'>best-first search: {e(document.message)}</p>" if searched else ""
    return (
        f"<h1>{e(w.composition)}</h1><p class='sub'>{e(document.scenario)}: the winner "
        f"({e(w.boundary_pair)} boundary pair)</p>{certificate}<table class='figures'>{figures}</table>"
        f"<p class='sub'>{_legend()}</p><h2>Candidates</h2>{ranking}"
    )


def _obstacle_label(document: ResultDocument, index: int) -> str:
    obstacles = document.task.obstacles
    return obstacle_label(obstacles[index], index) if 0 <= index < len(obstacles) else f"task.obstacles[{index}]"


def _figure(value: float | int | None, scale: float, spec: str) -> str:
    """``value`` times ``scale`` formatted by ``spec``; ``-`` for a figure written as null."""
    return "-" if value is None else format(value * scale, spec)


def _legend() -> str:
    swatches = " ".join(
        f"<span style='color:{KIND_COLOURS[k]}'>&#9632;</span> {html.escape(KIND_LABELS[k])}" for k in KIND_COLOURS
    )
    return (
        f"{swatches}; <span style='color:#d9534f'>&#9679;</span> obstacles (mesh: the clearance margin), "
        "<span style='color:#16a34a'>&#9679;</span> start, <span style='color:#2563eb'>&#9679;</span> goals on the "
        "way, <span style='color:#222'>&#9679;</span> goal, "
        "line: the tool's path"
    )


def _ranking(candidates: tuple[CandidateRecord, ...], winner: str, cost: str, limit: int = 60) -> str:
    """The table of candidates: the verified ranked by the task's objective (``cost``, its
    descriptor; a lexicographic order's tie-breaks get a column each), then the others by cost."""
    objective = _objective(cost)
    verified = [c for c in candidates if c.status == CandidateStatus.OPTIMAL and c.cost is not None]
    if objective.then and all(c.design is not None for c in verified):
        verified = objective.rank(
            verified, lambda c: cast(float, c.cost), lambda c: cast(Design, c.design), lambda c: c.candidate
        )
    else:
        verified.sort(key=lambda c: (cast(float, c.cost), c.candidate))
        objective = Objective(objective.terms)  # no design recorded: no tie-break columns
    chosen = {id(c) for c in verified}
    rest = sorted(
        (c for c in candidates if id(c) not in chosen),
        key=lambda c: (c.cost if c.cost is not None else np.inf, c.candidate),
    )
    ranked = verified + rest
    e = html.escape
    extra = "".join(f"<th>{e(name)}</th>" for name in objective.then)
    lines = [
        f"<table class='ranking'><tr><th>#</th><th>candidate</th><th>status</th><th>cost</th>{extra}<th>iterations</th>"
    ]
    for rank, c in enumerate(ranked[:limit], 1):
        cost_text = _figure(c.cost, 1, ".4g")
        status = c.status + (f" at {c.pruned_at_iteration}" if c.pruned_at_iteration is not None else "")
        mark = " class='winner'" if c.candidate == winner else ""
        iterations = "-" if c.iterations is None else c.iterations
        breaks = "".join(
            f"<td>{'-' if c.design is None else _figure(getattr(c.design, name), 1, '.4g')}</td>"
            for name in objective.then
        )
        lines.append(
            f"<tr{mark}><td>{rank}</td><td>{e(c.candidate)}</td><td>{e(status)}</td><td>{cost_text}</td>"
            f"{breaks}<td>{iterations}</td></tr>"
        )
    lines.append("</table>")
    if len(ranked) > limit:
        lines.append(f"<p class='sub'>… and {len(ranked) - limit} more (result.json)</p>")
    return "".join(lines)


def _objective(cost: str) -> Objective:
    """The objective a document names (an unreadable one ranks by the cost alone)."""
    try:
        return parse_objective(cost)
    except ValueError:
        return Objective()


# -- the page -------------------------------------------------------------------------------------
def _asset(name: str) -> str:
    return resources.files("modular_robots.viewer_assets").joinpath(name).read_text(encoding="utf-8")


def page(scene: dict, panel_html: str, title: str) -> str:
    """The whole page: styles, the panel, the player, three.js and the scene, inlined."""
    data = json.dumps(scene, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_asset('viewer.css')}</style></head><body>"
        f"<div id='view'></div><aside id='panel'>{panel_html}</aside>"
        "<div id='player'><button id='play' type='button'>Pause</button>"
        "<input id='time' type='range' min='0' max='1000' value='0' step='1'><span id='clock'></span></div>"
        f"<script type='application/json' id='scene-data'>{data}</script>"
        f"<script>{_asset('three.min.js')}</script><script>{_asset('OrbitControls.js')}</script>"
        f"<script>{_asset('viewer.js')}</script></body></html>\n"
    )
