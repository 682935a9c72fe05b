"""Make the body the ``tshirt_on_body`` scene dresses: ``config/meshes/mannequin.obj`` (a display
form with arms held out at the T-shirt's sleeve angle, generated here: no licensed body model), and
``config/meshes/tshirt_body.obj``, the shipped T-shirt with its two panels three times as far
apart (a shirt cut for a body 0.2 m deep; the same vertices, in the same order, so its landmarks
file is the T-shirt's).

The form, in metres with z up and the front towards −y: a torso lofted through elliptic
sections (half-widths and half-depths by height, waist to chest to shoulders), a capsule across
the shoulders, a neck and two arms (capsules from the shoulders out and down at 15°, into the
sleeves), joined into one closed surface by manifold3d's boolean union (through trimesh). Its
shoulders top out at 0.63 above the form's origin, where the shirt's shoulder seam (y = 0.65 in
the shirt's own frame) comes to rest.

Run ``.venv/bin/python tools/make_mannequin.py``; the output is the same bytes every time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

OUT = Path(__file__).resolve().parents[1] / "config" / "meshes"
#: sections of the torso: (height, half-width, half-depth), metres (the shirt's hem at 0)
SECTIONS = [
    (-0.15, 0.15, 0.10),
    (0.05, 0.155, 0.095),
    (0.25, 0.165, 0.10),
    (0.42, 0.175, 0.105),
    (0.54, 0.17, 0.095),
    (0.60, 0.14, 0.08),
]
AROUND = 48


def torso() -> trimesh.Trimesh:
    rings = []
    t = np.linspace(0, 2 * np.pi, AROUND, endpoint=False)
    for z, a, b in SECTIONS:
        rings.append(np.stack([a * np.cos(t), b * np.sin(t), np.full_like(t, z)], axis=1))
    v = np.concatenate([*rings, [[0, 0, SECTIONS[0][0]], [0, 0, SECTIONS[-1][0]]]])
    faces = []
    for r in range(len(rings) - 1):
        for k in range(AROUND):
            a, b = r * AROUND + k, r * AROUND + (k + 1) % AROUND
            c, d = a + AROUND, b + AROUND
            faces += [[a, b, d], [a, d, c]]
    bottom, top = len(v) - 2, len(v) - 1
    last = (len(rings) - 1) * AROUND
    for k in range(AROUND):
        faces.append([bottom, (k + 1) % AROUND, k])
        faces.append([top, last + k, last + (k + 1) % AROUND])
    m = trimesh.Trimesh(v, faces, process=True)
    m.fix_normals()
    return m


def capsule(a, b, radius) -> trimesh.Trimesh:
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.linalg.norm(b - a))
    m = trimesh.creation.capsule(height=length, radius=radius, count=[24, 24])
    # trimesh's capsule runs along z, centred; turn it onto a→b
    m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], (b - a) / length))
    m.apply_translation((a + b) / 2)
    return m


def mannequin() -> trimesh.Trimesh:
    down = np.tan(np.radians(15.0))
    parts = [
        torso(),
        capsule((-0.15, 0, 0.57), (0.15, 0, 0.57), 0.06),  # shoulders
        capsule((0, 0, 0.58), (0, 0, 0.80), 0.055),  # neck
    ]
    for side in (-1, 1):  # arms out into the sleeves
        a = np.array([side * 0.17, 0.0, 0.545])
        b = a + np.array([side * 0.36, 0.0, -0.36 * down])
        parts.append(capsule(a, b, 0.04))
    body = trimesh.boolean.union(parts, engine="manifold")
    body.merge_vertices()
    return body


def main() -> None:
    body = mannequin()
    body.export(OUT / "mannequin.obj")
    print(OUT / "mannequin.obj", len(body.vertices), "vertices", len(body.faces), "triangles")
    shirt = trimesh.load(OUT / "tshirt.obj", process=False, maintain_order=True)
    v = np.array(shirt.vertices)
    v[:, 2] *= 3.0
    lines = ["# the T-shirt cut for a body: tools/make_mannequin.py"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in shirt.faces]
    (OUT / "tshirt_body.obj").write_text("\n".join(lines) + "\n")
    (OUT / "tshirt_body.landmarks.yaml").write_text(
        (OUT / "tshirt.landmarks.yaml").read_text().replace("tshirt.obj", "tshirt_body.obj")
    )
    print(OUT / "tshirt_body.obj", len(v), "vertices")


if __name__ == "__main__":
    main()
