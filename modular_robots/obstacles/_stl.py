"""Reading STL files, binary and ASCII, into an array of triangles (NumPy only: the format is a
list of triangles, and the checks here say what is wrong with a file in the scenario's terms)."""

from __future__ import annotations

import hashlib
import os
import re
import stat
from pathlib import Path

import numpy as np

__all__ = ["read_stl", "stl_bytes", "welded", "MAX_TRIANGLES", "MAX_VISUAL_TRIANGLES", "MAX_BYTES", "StlError"]

#: The most triangles a mesh obstacle may have: each distance query bounds its distance to every
#: triangle (NumPy, about 0.1 ms a thousand), so a larger mesh is better decimated.
MAX_TRIANGLES = 50_000
#: The most triangles a visual mesh may have (a binary STL of :data:`MAX_BYTES`): only drawn.
MAX_VISUAL_TRIANGLES = 300_000
#: The largest file read [bytes]: an ASCII file of :data:`MAX_TRIANGLES` triangles.
MAX_BYTES = 300 * MAX_TRIANGLES
_BINARY_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
_NUMBER = r"([^\s]+)"
_VERTEX = re.compile(rb"\bvertex\s+" + (_NUMBER.encode() + rb"\s+") * 2 + _NUMBER.encode())
_FACET = re.compile(rb"\bendfacet\b")


class StlError(ValueError):
    """What is wrong with an STL file, naming it."""


def read_stl(path: Path, max_triangles: int | None = None) -> tuple[np.ndarray, str]:
    """The triangles ``(T, 3, 3)`` (three corners each, in the file's units) of the binary or
    ASCII STL file at ``path``, and the SHA-256 of its bytes (hexadecimal); :class:`StlError` if
    it is not one, holds no triangle, more than ``max_triangles`` (:data:`MAX_TRIANGLES` for an
    obstacle), or a corner that is not a finite number."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block, /dev/zero never ends
            raise StlError(f"{path} is not a regular file (a folder, device or pipe)")
        with open(path, "rb") as f:
            data = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise StlError(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_BYTES:
        raise StlError(f"{path} has more than {MAX_BYTES} bytes; a mesh is smaller (decimate it)")
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * count:  # binary, even when its header begins with "solid"
            corners = np.frombuffer(data, _BINARY_RECORD, count, 84)["corners"].astype(float)
            return _checked(corners, path, max_triangles), hashlib.sha256(data).hexdigest()
    if data.lstrip()[:5].lower() != b"solid":
        raise StlError(
            f"{path} is not an STL file: neither binary (84 + 50 bytes a triangle, {len(data)} bytes) "
            "nor ASCII (beginning with 'solid')"
        )
    if not data.rstrip().rsplit(b"\n", 1)[-1].strip().lower().startswith(b"endsolid"):
        raise StlError(f"{path}: an ASCII STL cut short (it does not end with 'endsolid'): copy it again")
    vertices = _VERTEX.findall(data)
    facets = len(_FACET.findall(data))
    if len(vertices) != 3 * facets:
        raise StlError(f"{path}: expected three vertices a facet, got {len(vertices)} vertices in {facets} facets")
    try:
        corners = np.array([[float(x) for x in v] for v in vertices], dtype=float)
    except ValueError:
        bad = next(v for v in vertices if not all(_is_number(x) for x in v))
        text = b" ".join(bad).decode(errors="replace")
        raise StlError(f"{path}: a vertex that is not three numbers: {text!r:.80}") from None
    return _checked(corners.reshape(-1, 3, 3), path, max_triangles), hashlib.sha256(data).hexdigest()


def stl_bytes(triangles: np.ndarray, header: str = "modular-robots") -> bytes:
    """Binary STL of ``triangles`` ``(T, 3, 3)`` (corners counter-clockwise seen from outside;
    normals from them), the record :func:`read_stl` reads."""
    corners = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    records = np.zeros(len(corners), _BINARY_RECORD)
    records["normal"] = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    records["corners"] = corners
    return header.encode()[:80].ljust(80, b" ") + len(corners).to_bytes(4, "little") + records.tobytes()


def welded(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (V, 3), faces (T, 3))`` of ``triangles`` ``(T, 3, 3)``, equal corners made one
    vertex: what a renderer takes."""
    vertices, faces = np.unique(np.asarray(triangles, dtype=float).reshape(-1, 3), axis=0, return_inverse=True)
    return vertices, faces.reshape(-1, 3)


def _checked(triangles: np.ndarray, path: Path, max_triangles: int | None) -> np.ndarray:
    most = MAX_TRIANGLES if max_triangles is None else max_triangles
    if len(triangles) == 0:
        raise StlError(f"{path} holds no triangle")
    if len(triangles) > most:
        raise StlError(f"{path} has {len(triangles)} triangles; at most {most} (decimate it)")
    finite = np.isfinite(triangles).all(axis=(1, 2))
    if not finite.all():
        index = int(np.argmin(finite))
        raise StlError(
            f"{path}: triangle {index} has a corner that is not a finite number: {triangles[index].tolist()}"
        )
    return triangles


def _is_number(text: bytes) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
