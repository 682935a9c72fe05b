"""Would reusing the self-contact search across steps pay on the ``tshirt`` scene? Steps the scene
(as it ships: vbd at 1/60 s, self-collision) and prints, second by second, how far its particles
move a step; then, over the next 2 s, what fraction of the search's tasks (the subtree pairs of
``collision_tree``, which a per-task candidate list would keep or make again) would have to search
again each step if each kept its list until its particles had moved a ``budget`` in all (the sum
over steps of the task's largest move); and how many pairs a search finds with its reaches grown
by a ``skin`` (what such a list would hold and filter every step).

    .venv/bin/python tools/self_contact_reuse.py

(docs/BENCHMARKS.md §11: not built, by these figures.)
"""

import numpy as np

from cloth_sim.contact.collision_tree import TriangleTree
from cloth_sim.scene import load_scene


def _task_particles(tree: TriangleTree) -> list:
    """Each task's particles: the corners of the items of its two subtrees."""
    n_tris = len(tree.tris)

    def node(a):
        items = tree.order[tree.first[a] : tree.end[a]]
        tris = items[items < n_tris]
        return np.concatenate(
            [tree.tris[tris].ravel(), tree.orphans[items[items >= n_tris] - n_tris]]
        )

    return [np.unique(np.concatenate([node(a), node(b)])) for a, b in tree.tasks]


def _moves(sim, steps: int) -> np.ndarray:
    """``(steps, n)``: how far each particle moved in each of the next ``steps`` steps."""
    out = np.empty((steps, sim.model.n_particles))
    for k in range(steps):
        prev = sim.positions.copy()
        sim.step()
        out[k] = np.linalg.norm(sim.positions - prev, axis=1)
    return out


def main() -> None:
    sim = load_scene("tshirt").build_simulator()
    sc = sim.stages[2]  # the self-collision stage: its triangles and topology
    print("second  per-step move (mm): max    p99    p90    median")
    for second in range(1, 6):
        q = np.percentile(_moves(sim, 60)[-10:], [100, 99, 90, 50]) * 1e3
        print(f"{second:6d}  {q[0]:27.3f} {q[1]:6.3f} {q[2]:6.3f} {q[3]:8.4f}")
    tree = TriangleTree(sc.triangles, sim.model.positions, sc.features)
    parts = _task_particles(tree)
    moves = _moves(sim, 120)
    print(f"\n{len(parts)} tasks, {np.mean([len(p) for p in parts]):.0f} particles a task")
    print("budget (mm)  tasks searching again a step")
    for budget in (0.5e-3, 1e-3, 2e-3, 4e-3):
        used, again = np.zeros(len(parts)), []
        for d in moves:
            used += [d[p].max() for p in parts]
            over = used > budget
            again.append(over.mean())
            used[over] = 0.0
        print(f"{budget * 1e3:11.1f}  {np.mean(again):6.1%}")
    reach = 0.5 * sc.thickness + 0.1 * sc.thickness  # vbd's reach at rest: τ/2 and its allowance
    print("\nskin (mm)  particle-triangle pairs  edge pairs")
    for skin in (0.0, 1e-3, 2e-3, 4e-3):
        vf, _, ee, _ = tree.pairs(sim.positions, np.full(sim.model.n_particles, reach + skin))
        print(f"{skin * 1e3:9.1f}  {len(vf):23d}  {len(ee):10d}")


if __name__ == "__main__":
    main()
