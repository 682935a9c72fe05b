"""Triangle meshes as cloth: reading a file, welding seams, checking the mesh, and its springs.

:meth:`cloth_sim.model.ClothModel.from_mesh` is the public entry; this module holds its parts, each
a
pure function of arrays:

* :func:`read_mesh` — a path (OBJ, PLY, STL, glTF/GLB, OFF, through `trimesh`_, imported only here
  and only when a file is read) or ``(vertices, faces)`` arrays, scaled to metres;
* :func:`weld` — vertices at the same position (exporters split them at texture seams; STL stores
  every triangle's corners apart) become one particle; a mesh without such duplicates keeps its
  vertex order;
* :func:`check_mesh` — every way a mesh can be unusable as cloth, each a ``ValueError`` naming the
  source and the element;
* :func:`mesh_springs` — one ``structural`` spring per unique edge and one ``bend`` spring per
  interior edge, joining the two vertices opposite it (Provot's bend springs on a grid are the same
  idea: they resist folding across the edge between them);
* :func:`lumped_masses` — each vertex carries a third of the area of each of its triangles times
  the areal density.

.. _trimesh: https://trimesh.org
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

#: the file formats read (by extension, case-insensitive)
MESH_FORMATS = ("obj", "ply", "stl", "gltf", "glb", "off")
#: mesh files larger than this are refused unread
MAX_MESH_BYTES = 256 << 20
#: meshes with more triangles than this are refused (a 2-core machine steps ~10⁵ in real time)
MAX_MESH_TRIANGLES = 2_000_000
#: a triangle whose area is below this fraction of its longest edge squared counts as degenerate
DEGENERATE_AREA = 1e-12


def read_mesh(source, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, str]:
    """``(vertices (n, 3) float64, faces (t, 3) int64, name)``: ``source`` is a path or a
    ``(vertices, faces)`` pair; ``vertices`` are multiplied by ``scale`` (metres per file unit).
    Only the reading is checked here (readable, known format, size bound, array shapes);
    :func:`check_mesh` checks the contents."""
    if not (
        isinstance(scale, (int, float))
        and not isinstance(scale, bool)
        and np.isfinite(scale)
        and scale > 0
    ):
        raise ValueError(
            f"from_mesh: scale must be a finite number > 0 (metres per file unit), got {scale!r}"
        )
    if isinstance(source, (str, os.PathLike)):
        vertices, faces = _read_file(Path(source))
        name = str(source)
    else:
        try:
            vertices, faces = source
        except (TypeError, ValueError):
            raise ValueError(
                "from_mesh: source must be a mesh file path or a (vertices, faces) "
                f"pair, got {type(source).__name__}"
            ) from None
        name = "(vertices, faces)"
    try:
        v = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: vertices must be numbers, shape (n, 3)") from None
    try:
        f = np.array(faces)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: faces must be integers, shape (t, 3)") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{name}: vertices must have shape (n, 3), got {v.shape}")
    if f.size == 0:
        raise ValueError(f"{name}: the mesh has no triangles")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"{name}: faces must be triangles, shape (t, 3), got {f.shape}")
    if not (
        np.issubdtype(f.dtype, np.integer)
        or (
            np.issubdtype(f.dtype, np.floating)
            and np.all(np.isfinite(f))
            and np.all(f == np.round(f))
        )
    ):
        raise ValueError(f"{name}: faces must hold integer vertex indices")
    if len(f) > MAX_MESH_TRIANGLES:
        raise ValueError(
            f"{name}: {len(f)} triangles, more than the {MAX_MESH_TRIANGLES} accepted"
        )
    return v * float(scale), f.astype(np.int64), name


def _read_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    where = str(path)
    ext = path.suffix.lower().lstrip(".")
    if ext not in MESH_FORMATS:
        raise ValueError(
            f"{where}: unknown mesh format {path.suffix or '(no extension)'!r}; "
            f"expected one of {', '.join('.' + e for e in MESH_FORMATS)}"
        )
    try:
        if not path.is_file():
            raise ValueError(f"{where}: no such mesh file")
        size = path.stat().st_size
    except OSError as e:
        raise ValueError(f"{where}: cannot be read ({e.strerror or e})") from None
    if size > MAX_MESH_BYTES:
        raise ValueError(
            f"{where}: {size} bytes, larger than the {MAX_MESH_BYTES} bytes accepted "
            f"for a mesh file"
        )
    import trimesh  # ~0.6 s to import: only when a file is read

    try:
        mesh = trimesh.load(
            str(path), file_type=ext, force="mesh", process=False, maintain_order=True
        )
    except IndexError as e:  # a face naming a vertex the file does not have, or a cut-short file
        raise ValueError(
            f"{where}: cannot be read as {ext.upper()}: a face refers to a vertex index "
            f"out of range, or the file is cut short ({e})"
        ) from None
    except Exception as e:  # noqa: BLE001 — any reader failure is the file's: say so, name it
        raise ValueError(
            f"{where}: cannot be read as {ext.upper()} ({type(e).__name__}: {str(e)[:200]})"
        ) from None
    faces = getattr(mesh, "faces", None)
    vertices = getattr(mesh, "vertices", None)
    if faces is None or vertices is None or len(faces) == 0:
        raise ValueError(f"{where}: the mesh has no triangles")
    return np.asarray(vertices), np.asarray(faces)


#: a mesh file's named vertices live beside it, in ``<stem>.landmarks.yaml`` (``name: index``)
LANDMARKS_SUFFIX = ".landmarks.yaml"


def read_landmarks(source, n_vertices: int) -> dict[str, int]:
    """The named vertices of mesh file ``source`` (collar, shoulders, sleeve ends, hem corners of a
    garment: what a task's key points and metrics name), read from ``<stem>.landmarks.yaml``
    beside it: a mapping of names (letters, digits and ``_``) to vertex indices of the file,
    0-based. ``{}`` for a file without one, or for arrays. A malformed one raises ``ValueError``
    naming the file and the entry."""
    if not isinstance(source, (str, os.PathLike)):
        return {}
    path = Path(source)
    side = path.with_name(path.stem + LANDMARKS_SUFFIX)
    if not side.is_file():
        return {}
    import yaml

    try:
        data = yaml.safe_load(side.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise ValueError(f"{side}: cannot be read as YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{side}: expected a mapping of landmark names to vertex indices")
    out = {}
    for name, index in data.items():
        if not (isinstance(name, str) and name.isidentifier() and name.isascii()):
            raise ValueError(
                f"{side}: landmark name {name!r} is not accepted: expected letters, digits and _"
            )
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < n_vertices:
            raise ValueError(
                f"{side}: landmark {name} = {index!r} is not accepted: expected a vertex index "
                f"of {path.name}, an integer in [0, {n_vertices - 1}]"
            )
        out[name] = index
    return out


def weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(vertices, faces, index)``: vertices with bit-equal coordinates merged into the first of
    them, kept in the order of first appearance (so a mesh without duplicates is unchanged);
    ``index[i]`` is the welded index of input vertex ``i``. ``-0.0`` equals ``0.0``."""
    v = vertices + 0.0  # -0.0 → 0.0
    _, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if len(first) == len(v):
        return vertices, faces, np.arange(len(v))
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    index = rank[inverse]
    return vertices[first[order]], index[faces], index


def check_indices(vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """``ValueError`` naming ``name`` and the element for: no triangles, a vertex index out of
    range, a non-finite coordinate (what welding needs sound; :func:`check_mesh` checks the
    rest)."""
    n, t = len(vertices), len(faces)
    if t == 0:
        raise ValueError(f"{name}: the mesh has no triangles")
    bad = np.flatnonzero(((faces < 0) | (faces >= n)).any(axis=1))
    if len(bad):
        i = int(bad[0])
        raise ValueError(
            f"{name}: triangle {i} refers to vertex {faces[i].tolist()}, out of range: "
            f"the mesh has {n} vertices (indices 0 to {n - 1})"
        )
    bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
    if len(bad):
        raise ValueError(
            f"{name}: vertex {int(bad[0])} has a non-finite coordinate {vertices[bad[0]].tolist()}"
        )


def check_mesh(vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """:func:`check_indices`, and a ``ValueError`` naming ``name`` and the element for: a
    degenerate triangle (a repeated corner or zero area), the same triangle twice, an edge shared
    by more than two triangles, a vertex in no triangle."""
    check_indices(vertices, faces, name)
    n = len(vertices)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest2 = np.max(
        [((b - a) ** 2).sum(1), ((c - b) ** 2).sum(1), ((a - c) ** 2).sum(1)], axis=0
    )
    repeated = (
        (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    )
    bad = np.flatnonzero(repeated | (area2 <= DEGENERATE_AREA * longest2) | (longest2 == 0))
    if len(bad):
        i = int(bad[0])
        raise ValueError(
            f"{name}: triangle {i} (vertices {faces[i].tolist()}) is degenerate: "
            f"zero area (after welding vertices at the same position)"
        )
    key = np.sort(faces, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        dup = key[first[counts > 1][0]]
        same = np.flatnonzero((key == dup).all(axis=1))[:2].tolist()
        raise ValueError(
            f"{name}: triangles {same[0]} and {same[1]} have the same vertices {dup.tolist()}"
        )
    edges, _, counts = half_edges(faces, n)
    over = np.flatnonzero(counts > 2)
    if len(over):
        e = edges[over[0]]
        raise ValueError(
            f"{name}: non-manifold edge between vertices {int(e[0])} and {int(e[1])}: "
            f"shared by {int(counts[over[0]])} triangles (a cloth edge has one or two)"
        )
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    if not used.all():
        raise ValueError(
            f"{name}: vertex {int(np.flatnonzero(~used)[0])} belongs to no triangle "
            f"(a particle needs a triangle's area for its mass)"
        )


def half_edges(faces: np.ndarray, n: int):
    """``(edges (e, 2), group, counts)``: the unique undirected edges (sorted ends, in key order),
    for each half-edge ``3·f + k`` (edge ``faces[f, k]–faces[f, k+1]``) its edge's index, and how
    many triangles share each edge."""
    lo = np.minimum(faces, np.roll(faces, -1, axis=1)).ravel()
    hi = np.maximum(faces, np.roll(faces, -1, axis=1)).ravel()
    keys = lo * np.int64(n) + hi
    uniq, group, counts = np.unique(keys, return_inverse=True, return_counts=True)
    edges = np.stack(np.divmod(uniq, np.int64(n)), axis=1)
    return edges, group.ravel(), counts


def mesh_springs(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(structural (e, 2), bend (b, 2))``: every unique edge (ends sorted, edges in order of
    their ends), and for each interior edge (two triangles), the two vertices opposite it, in the
    same order. A mesh passed by :func:`check_mesh` has no edge of more than two triangles."""
    edges, group, counts = half_edges(faces, n)
    opposite = np.roll(faces, -2, axis=1).ravel()  # the corner facing half-edge 3f + k
    order = np.argsort(group, kind="stable")
    g, o = group[order], opposite[order]
    pair = np.flatnonzero(g[1:] == g[:-1])  # consecutive half-edges of one interior edge
    bend = np.stack([o[pair], o[pair + 1]], axis=1)
    return edges, np.sort(bend, axis=1)


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def lumped_masses(vertices: np.ndarray, faces: np.ndarray, density: float) -> np.ndarray:
    """Each vertex's mass: ``density`` (kg/m²) × a third of the area of each of its triangles."""
    third = triangle_areas(vertices, faces) * (float(density) / 3.0)
    return np.bincount(faces.ravel(), weights=np.repeat(third, 3), minlength=len(vertices))


def vertices_in_box(positions: np.ndarray, lo, hi) -> np.ndarray:
    """Indices of the vertices inside the axis-aligned box ``[lo, hi]`` (bounds included)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    return np.flatnonzero(np.all((positions >= lo) & (positions <= hi), axis=1))
