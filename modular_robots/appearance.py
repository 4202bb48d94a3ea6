"""How a robot looks: one colour per module kind, written into the URDF's ``<visual>`` materials
(RViz shows them) and read back from there by the page (:mod:`~modular_robots.viewer`), so the two
and the page's legend always agree."""

from __future__ import annotations

__all__ = ["KIND_COLOURS", "KIND_LABELS", "material", "visual_shapes", "colour_of_rgba"]

#: Colour of each module kind and of the payload, as ``#rrggbb``.
KIND_COLOURS = {
    "base": "#6c757d",
    "joint": "#f0a202",
    "link": "#2f6db5",
    "effector": "#8e44ad",
    "payload": "#c9a227",
}

#: What the page's legend calls each kind.
KIND_LABELS = {
    "base": "base",
    "joint": "joint module",
    "link": "link",
    "effector": "effector",
    "payload": "payload",
}


def material(kind: str) -> str:
    """The URDF ``<material>`` of a module kind (a key of :data:`KIND_COLOURS`), colour inline so
    that every reader (urdfdom, yourdfpy, RViz) takes it without a lookup."""
    hex_colour = KIND_COLOURS[kind]
    rgba = " ".join(f"{int(hex_colour[k : k + 2], 16) / 255:.4g}" for k in (1, 3, 5))
    return f'<material name="{kind}"><color rgba="{rgba} 1"/></material>'


def visual_shapes(radius: float, length: float, kind: str, centre=(0.0, 0.0, 0.0)) -> str:
    """``<visual>`` elements of a collision primitive centred at ``centre`` [m] in its link: a
    sphere of ``radius`` if ``length`` is 0, else a capsule along z (URDF has none: its cylinder
    and two end spheres), in the colour of ``kind``."""
    x, y, z = (float(c) for c in centre)
    r, h = repr(float(radius)), float(length)
    parts = [((x, y, z), f'<sphere radius="{r}"/>')]
    if h > 0.0:
        parts = [
            ((x, y, z), f'<cylinder radius="{r}" length="{h!r}"/>'),
            ((x, y, z - h / 2), f'<sphere radius="{r}"/>'),
            ((x, y, z + h / 2), f'<sphere radius="{r}"/>'),
        ]
    paint = material(kind)
    return "".join(
        f'    <visual>\n      <origin xyz="{a!r} {b!r} {c!r}" rpy="0 0 0"/>\n'
        f"      <geometry>{geometry}</geometry>\n      {paint}\n    </visual>\n"
        for (a, b, c), geometry in parts
    )


def colour_of_rgba(rgba) -> str:
    """``#rrggbb`` of an RGBA colour whose components are in [0, 1] (alpha ignored)."""
    return "#" + "".join(f"{round(min(max(float(c), 0.0), 1.0) * 255):02x}" for c in list(rgba)[:3])
