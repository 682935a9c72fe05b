"""``cloth-sim dataset``'s speed and size: the same dataset written at 1 and at 2 workers (a local
Ray each), episodes and frames per second (Ray's start included), MB per episode, and whether the
two are the same bytes.

    .venv/bin/python -m cloth_sim.bench.dataset [--task ClothFold TshirtFold] [--episodes 40 6]

The tasks' initial states are generated into the user cache first (untimed).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path


def tree(root: Path) -> dict:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", nargs="+", default=["ClothFold", "TshirtFold"])
    p.add_argument("--episodes", nargs="+", type=int, default=[40, 6])
    p.add_argument("--policy", default="scripted")
    args = p.parse_args(argv)
    from cloth_sim.dataset import engine, rollout

    print(
        "| task | episodes | frames | workers | s | episodes/s | frames/s | MB/episode "
        "| same bytes |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for task, n in zip(args.task, args.episodes):
        env = rollout.make_env(task, "key_point", 128)
        for e in range(n):  # the episodes' initial states into the cache, untimed
            env.reset(seed=rollout.episode_seed(0, e))
        work = Path(tempfile.mkdtemp(prefix="cloth_sim_dataset_"))
        try:
            first = None
            for workers in (1, 2):
                out = work / str(workers)
                t = time.perf_counter()
                w = engine.generate(task, out, args.policy, n, workers=workers, progress=False)
                s = time.perf_counter() - t
                files = tree(out)
                size = sum(len(b) for b in files.values()) / 1e6 / n
                same = "—" if first is None else ("yes" if files == first else "NO")
                first = first or files
                frames = w.info["total_frames"]
                print(
                    f"| {task} | {n} | {frames} | {workers} | {s:.1f} | {n / s:.2f} | "
                    f"{frames / s:.1f} | {size:.3f} | {same} |",
                    flush=True,
                )
        finally:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
