"""What a sweep costs beyond its runs, in one process, side by side:

1. ``throughput``: 100 runs of the 32×32 hanging_provot scene, 1 s of simulated time each (the
   scene's symplectic Euler at dt = 1 ms, its strain limit on), 30 frames per second into each
   run's bag — a bare Python loop over :func:`cloth_sim.sweep.run.execute` (the same runs, the same
   files, no Ray), then ``cloth-sim sweep`` on a local Ray with 1 and with 2 workers: runs per
   second, the speed-up of 2 workers over 1 and the overhead per run of 1 worker over the bare
   loop.
2. ``memory``: 10,000 short runs (a 4×4 cloth, 10 steps, no bag) through Ray at 2 workers, the
   driver's resident memory sampled every 0.5 s against the runs done: it must not grow with them.

    .venv/bin/python -m cloth_sim.bench.sweep [throughput] [memory] [--runs 100]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import threading
import time
from pathlib import Path

import yaml


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def throughput(runs: int, root: Path) -> None:
    from cloth_sim.sweep import engine, load_spec
    from cloth_sim.sweep.run import execute

    spec_path = root / "hanging.yaml"
    spec_path.write_text(
        yaml.safe_dump(
            {
                "scene": "hanging_provot",
                "duration": 1.0,
                "frames": 30,
                "seed": 1,
                "random": {"samples": runs, "wind.strength": {"uniform": [0.0, 2.0]}},
            }
        )
    )
    spec = load_spec(spec_path)
    t = time.perf_counter()
    for run in spec.runs():
        row = execute(spec, run, root / "bare")
        assert row["status"] == "ok", row
    bare = time.perf_counter() - t
    import logging

    import ray

    times, starts = {}, {}
    warm = root / "warm.yaml"
    warm.write_text(
        yaml.safe_dump(
            {
                "scene": "hanging_provot",
                "duration": 0.01,
                "frames": 30,
                "seed": 2,
                "random": {"samples": 4, "wind.strength": {"uniform": [0.0, 2.0]}},
            }
        )
    )
    for workers in (1, 2):
        t = time.perf_counter()
        ray.init(
            address="local",
            num_cpus=workers,
            include_dashboard=False,
            logging_level=logging.WARNING,
            runtime_env={
                "env_vars": {
                    "OPENBLAS_NUM_THREADS": "1",
                    "OMP_NUM_THREADS": "1",
                    "NUMBA_NUM_THREADS": "1",
                }
            },
        )
        # Ray's start, then its workers' (a process each, importing cloth_sim and loading the
        # kernels)
        engine.sweep(warm, root / f"warm{workers}", workers=workers, progress=False)
        starts[workers] = time.perf_counter() - t
        t = time.perf_counter()
        engine.sweep(spec_path, root / f"ray{workers}", workers=workers, progress=False)
        times[workers] = time.perf_counter() - t
        ray.shutdown()
    print(
        f"# {runs} runs of the 32×32 hanging_provot scene, 1 s each (1000 steps, 31 frames to the "
        f"bag); {os.cpu_count()} cores"
    )
    print("| how | start-up s (Ray, workers warm) | sweep wall s | runs/s | per run ms |")
    print("|---|---|---|---|---|")
    for name, wall, start in (
        ("bare Python loop (no Ray)", bare, 0.0),
        ("Ray, 1 worker", times[1], starts[1]),
        ("Ray, 2 workers", times[2], starts[2]),
    ):
        print(
            f"| {name} | {start:.1f} | {wall:.1f} | {runs / wall:.2f} | {1e3 * wall / runs:.0f} |"
        )
    print(
        f"2 workers / 1 worker: {times[1] / times[2]:.2f}×; Ray 1 worker over the bare loop: "
        f"{100 * (times[1] / bare - 1):+.1f} % per run once started "
        f"({1e3 * (times[1] - bare) / runs:.0f} ms "
        f"per run), {100 * ((times[1] + starts[1]) / bare - 1):+.1f} % with its start-up"
    )


def memory(runs: int, root: Path) -> None:
    from cloth_sim.sweep import engine

    spec_path = root / "short.yaml"
    spec_path.write_text(
        yaml.safe_dump(
            {
                "scene": "hanging_provot",
                "duration": 0.01,
                "frames": 0,
                "seed": 1,
                "set": {"rows": 4, "cols": 4, "spacing": 0.33},
                "random": {"samples": runs, "wind.strength": {"uniform": [0.0, 2.0]}},
            }
        )
    )
    out = root / "short"
    samples, stop = [], threading.Event()

    def sample():
        t0 = time.perf_counter()
        while not stop.wait(0.5):
            done = sum(1 for _ in os.scandir(out / "runs")) if (out / "runs").exists() else 0
            samples.append((time.perf_counter() - t0, done, rss_mb()))

    before = rss_mb()
    th = threading.Thread(target=sample, daemon=True)
    th.start()
    t = time.perf_counter()
    engine.sweep(spec_path, out, workers=2, progress=False)
    wall = time.perf_counter() - t
    stop.set()
    th.join()
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"# {runs} short runs (4×4 cloth, 10 steps, no bag) on a local Ray, 2 workers: {wall:.1f} "
        "s, "
        f"{runs / wall:.0f} runs/s; driver resident memory before the sweep {before:.0f} MB, "
        f"peak {peak:.0f} MB"
    )
    print("| runs done | driver resident MB |")
    print("|---|---|")
    marks = [runs * f // 10 for f in range(1, 11)]
    for m in marks:
        s = next((s for s in samples if s[1] >= m), samples[-1] if samples else None)
        if s:
            print(f"| {s[1]} | {s[2]:.0f} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", nargs="*", default=["throughput", "memory"])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--short-runs", type=int, default=10_000)
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    try:
        if "throughput" in args.what:
            throughput(args.runs, root)
        if "memory" in args.what:
            memory(args.short_runs, root)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
