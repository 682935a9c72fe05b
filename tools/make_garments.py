"""Make the shipped garments, ``config/meshes/tshirt.obj`` and ``config/meshes/towel.obj``, and the
``twist`` scene's sheet, ``config/meshes/twist_sheet.obj``.

Each outline is a polygon in metres, its sides cut into pieces of about ``EDGE`` and triangulated
by Shewchuk's Triangle (the ``triangle`` package) as a quality mesh: no angle below 28°, no
triangle larger than an equilateral one of side ``EDGE``, and no point added on the outline
(``Y``), so two panels cut from one outline share their seam vertices exactly.

* **T-shirt**: a front and a back panel from one outline, joined along the side, sleeve and
  shoulder seams (their vertices are shared), open at the neck, the two cuffs and the waist. The
  panels bulge apart by up to ``DEPTH`` away from the seams (a garment modelled around a body), so
  the shirt rests as made, with a few centimetres between its layers. The back panel's triangles
  are wound the other way, so every normal points out of the shirt.
* **Towel**: a 0.5 m × 0.8 m rectangle, hung from its two top corners by the ``towel`` scene.
* **Twist sheet**: the cloth of Newton's ``example_cloth_twist`` (its asset ``square_cloth.usd``
  scaled by 0.01): a 1.5 m × 1.0 m sheet of 50 × 50 vertices on a regular grid, each cell cut along
  the diagonal that alternates like a checkerboard (as that asset's; the vertices in the same
  order, x fastest). Not a quality mesh: the same triangles as the peer's, so the two solvers run
  one cloth.

Run ``.venv/bin/python tools/make_garments.py``; the output is the same bytes every time.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import triangle

OUT = Path(__file__).resolve().parent.parent / "config" / "meshes"
EDGE = 0.025  # m, target edge length
DEPTH = 0.05  # m, the most each T-shirt panel bulges away from the seams
FALLOFF = 0.06  # m, distance from a seam over which the bulge grows


def _polyline(points: np.ndarray, closed: bool = True) -> np.ndarray:
    """The outline's corners with points added along each side at about ``EDGE`` apart."""
    out = []
    n = len(points)
    for i in range(n if closed else n - 1):
        a, b = points[i], points[(i + 1) % n]
        pieces = max(1, int(round(np.linalg.norm(b - a) / EDGE)))
        out += [a + (b - a) * t for t in np.arange(pieces) / pieces]
    return np.array(out)


def _quality_mesh(outline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangle's quality mesh of a simple polygon (counter-clockwise), its outline unsplit."""
    n = len(outline)
    segments = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    area = np.sqrt(3) / 4 * EDGE**2
    out = triangle.triangulate({"vertices": outline, "segments": segments}, f"pq28Ya{area:.8f}")
    if len(out["vertices"]) < n or not np.allclose(out["vertices"][:n], outline):
        sys.exit("make_garments: Triangle changed the outline")
    return out["vertices"], out["triangles"]


def _tshirt_outline() -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The shirt's outline (counter-clockwise, metres, waist at y = 0) and which of its sides are
    seams (the rest are openings: waist, cuffs, neck)."""
    neck = [(0.09 * np.cos(t), 0.69 - 0.07 * np.sin(t)) for t in np.linspace(0.0, np.pi, 9)]
    corners = [
        (-0.25, 0.0),
        (0.25, 0.0),  # waist (opening)
        (0.25, 0.45),
        (0.48, 0.42),  # right side seam, right sleeve bottom seam
        (0.41, 0.56),
        (0.20, 0.65),  # right cuff (opening), sleeve top seam
        *neck,  # shoulder seam to (0.09, 0.69), neck
        (-0.20, 0.65),
        (-0.41, 0.56),  # left shoulder seam, left sleeve top seam
        (-0.48, 0.42),
        (-0.25, 0.45),
    ]  # left cuff (opening), sleeve bottom, side
    corners = np.array(corners)
    k = len(corners)
    openings = {0, 3, *range(6, 6 + len(neck) - 1), k - 3}  # sides i → i+1 that stay open
    seams = [(i, (i + 1) % k) for i in range(k) if i not in openings]
    return corners, seams


#: the T-shirt's named points on its outline (metres, the waist's middle at the origin): what a
#: garment task's key points and fold metric name (GarmentLab's collar, shoulders, sleeves, hem)
TSHIRT_LANDMARKS = {
    "hem_left": (-0.25, 0.0),
    "hem_right": (0.25, 0.0),
    "hem_middle": (0.0, 0.0),
    "armpit_left": (-0.25, 0.45),
    "armpit_right": (0.25, 0.45),
    "sleeve_left_bottom": (-0.48, 0.42),
    "sleeve_left_top": (-0.41, 0.56),
    "sleeve_right_bottom": (0.48, 0.42),
    "sleeve_right_top": (0.41, 0.56),
    "shoulder_left": (-0.20, 0.65),
    "shoulder_right": (0.20, 0.65),
    "collar_left": (-0.09, 0.69),
    "collar_right": (0.09, 0.69),
    "collar_middle": (0.0, 0.62),
}


def tshirt() -> tuple[np.ndarray, np.ndarray, dict]:
    corners, seams = _tshirt_outline()
    # cut the outline, remembering which points lie on a seam side
    points, on_seam = [], []
    k = len(corners)
    seam_sides = {a for a, _ in seams}
    for i in range(k):
        a, b = corners[i], corners[(i + 1) % k]
        pieces = max(1, int(round(np.linalg.norm(b - a) / EDGE)))
        for t in np.arange(pieces) / pieces:
            points.append(a + (b - a) * t)
            # a corner joins its two sides: on a seam if either side is one
            on_seam.append(i in seam_sides or (t == 0 and (i - 1) % k in seam_sides))
    outline = np.array(points)
    on_seam = np.array(on_seam)
    xy, tris = _quality_mesh(outline)
    # the bulge: 0 on the seams, growing to DEPTH away from them
    seam_pts = outline[on_seam]
    seam_segs = [
        (outline[i], outline[(i + 1) % len(outline)])
        for i in range(len(outline))
        if on_seam[i] and on_seam[(i + 1) % len(outline)]
    ]
    dist = np.full(len(xy), np.inf)
    for a, b in seam_segs:
        ab = b - a
        t = np.clip(((xy - a) @ ab) / (ab @ ab), 0.0, 1.0)
        dist = np.minimum(dist, np.linalg.norm(xy - (a + t[:, None] * ab), axis=1))
    dist = np.minimum(dist, np.min(np.linalg.norm(xy[:, None] - seam_pts[None], axis=2), axis=1))
    z = DEPTH * (1.0 - np.exp(-dist / FALLOFF))
    shared = np.zeros(len(xy), bool)
    shared[: len(outline)] = on_seam
    front = np.column_stack([xy, z])
    # the back panel: the same points mirrored through z = 0; seam points are the front's own
    back_index = np.where(shared, np.arange(len(xy)), len(xy) + np.cumsum(~shared) - 1)
    back = np.column_stack([xy[~shared], -z[~shared]])
    vertices = np.vstack([front, back])
    faces = np.vstack([tris, back_index[tris][:, ::-1]])
    # the named points: outline corners (a seam's are one vertex of both panels); the middle of the
    # neck and of the hem, once on the front panel and once on the back
    landmarks = {}
    for name, (x, y) in TSHIRT_LANDMARKS.items():
        i = int(np.flatnonzero(np.all(np.abs(outline - (x, y)) < 1e-9, axis=1))[0])
        if shared[i]:
            landmarks[name] = i
        else:
            landmarks[f"{name}_front"], landmarks[f"{name}_back"] = i, int(back_index[i])
    return vertices, faces, landmarks


def towel() -> tuple[np.ndarray, np.ndarray]:
    corners = np.array([(0.0, 0.0), (0.5, 0.0), (0.5, 0.8), (0.0, 0.8)])
    xy, tris = _quality_mesh(_polyline(corners))
    return np.column_stack([xy, np.zeros(len(xy))]), tris


def twist_sheet(
    n: int = 50, width: float = 1.5, height: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.linspace(-width / 2, width / 2, n), np.linspace(-height / 2, height / 2, n)
    vertices = np.array([(x, y, 0.0) for y in ys for x in xs])
    faces = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            faces += [(a, e, b), (a, d, e)] if (r + c) % 2 == 0 else [(a, d, b), (d, e, b)]
    return vertices, np.array(faces)


def write_obj(
    path: Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    title: str,
    how: str = "Triangle, quality mesh q28",
) -> None:
    lines = [
        f"# {title}",
        f"# made by tools/make_garments.py ({how}); units: metres",
        f"# {len(vertices)} vertices, {len(faces)} triangles",
    ]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def write_landmarks(path: Path, landmarks: dict, mesh: str) -> None:
    """``<stem>.landmarks.yaml``: the named vertices (0-based indices of the OBJ's vertices), read
    by :func:`cloth_sim.physics.mesh.read_landmarks`."""
    lines = [
        f"# named vertices of {mesh} (0-based, the file's vertex order); made by "
        "tools/make_garments.py"
    ]
    lines += [f"{name}: {index}" for name, index in landmarks.items()]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    v, f, landmarks = tshirt()
    write_obj(
        OUT / "tshirt.obj",
        v,
        f,
        "A T-shirt: front and back panels joined at the shoulders, sleeves and sides",
    )
    write_landmarks(OUT / "tshirt.landmarks.yaml", landmarks, "tshirt.obj")
    print(f"tshirt: {len(v)} vertices, {len(f)} triangles, {len(landmarks)} landmarks -> {OUT}")
    v, f = towel()
    write_obj(OUT / "towel.obj", v, f, "A 0.5 m x 0.8 m towel")
    print(f"towel: {len(v)} vertices, {len(f)} triangles -> {OUT / 'towel.obj'}")
    v, f = twist_sheet()
    write_obj(
        OUT / "twist_sheet.obj",
        v,
        f,
        "Newton's twist cloth: 1.5 m x 1.0 m, 50 x 50 vertices",
        "a regular grid, diagonals alternating",
    )
    print(f"twist_sheet: {len(v)} vertices, {len(f)} triangles -> {OUT / 'twist_sheet.obj'}")


if __name__ == "__main__":
    main()
