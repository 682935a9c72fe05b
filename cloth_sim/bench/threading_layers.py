"""ms/step of the hanging_provot cloth under each of numba's threading layers, side by side.

numba picks its threading layer once per process, so each layer runs in its own child process
(``NUMBA_THREADING_LAYER`` set), the layers taking turns for ``rounds`` rounds; the table gives
each layer's median. Two ways of stepping, both from the same state, 0.5 s after the release:

* *steady*: steps back to back (a sweep, a benchmark, ``cloth-sim run``);
* *ticks*: the steps of one 1/60 s tick, then the rest of the tick idle, as the node steps (the
  pool's workers fall asleep between ticks and must be woken for the next one).

Every layer must end at the same bits (the kernels' work is split the same way whatever runs it):
the table prints each run's state hash.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

LAYERS = ("omp", "tbb", "workqueue")


def _child(size: int, seconds: float) -> dict:
    import numba

    from ..scene import load_scene
    from .scene_hashes import state_hash

    sim = load_scene("hanging_provot").build_simulator(
        rows=size, cols=size, spacing=1.0 / (size - 1)
    )
    sim.advance(0.5)
    saved = sim.save_state()
    tau = sim.strain_limit
    n = max(1, int(round(seconds / sim.dt)))
    out = {"layer": numba.threading_layer(), "threads": numba.get_num_threads()}
    for label, limit in (("scene", tau), ("free", None)):
        sim.strain_limit = limit
        sim.restore_state(saved)
        t = time.perf_counter()
        sim.step(n)
        out[f"{label}_steady_ms"] = 1e3 * (time.perf_counter() - t) / n
        out[f"{label}_hash"] = state_hash(sim)
        sim.restore_state(saved)
        period = 1.0 / 60.0
        per_tick = max(1, int(round(period / sim.dt)))
        busy, steps = 0.0, 0
        while steps < n:
            t0 = time.perf_counter()
            k = min(per_tick, n - steps)
            sim.step(k)
            el = time.perf_counter() - t0
            busy += el
            steps += k
            time.sleep(max(0.0, period - el))
        out[f"{label}_ticks_ms"] = 1e3 * busy / n
    return out


def measure(size: int = 64, seconds: float = 1.0, rounds: int = 3, layers=LAYERS) -> dict:
    """``{layer: [result per round]}``; a layer that cannot load (its library missing) is left out
    with its error in ``{layer: str}``."""
    out: dict = {layer: [] for layer in layers}
    for _ in range(rounds):
        for layer in layers:
            if isinstance(out[layer], str):
                continue
            env = dict(os.environ, NUMBA_THREADING_LAYER=layer)
            p = subprocess.run(
                [sys.executable, "-m", __name__, "--child", str(size), str(seconds)],
                env=env,
                capture_output=True,
                text=True,
            )
            if p.returncode:
                out[layer] = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"
                continue
            out[layer].append(json.loads(p.stdout.strip().splitlines()[-1]))
    return out


def print_table(size: int = 64, seconds: float = 1.0, rounds: int = 3) -> dict:
    print(
        f"# hanging_provot {size}×{size}, {seconds:g} s simulated from t = 0.5 s, with the "
        f"scene's strain limit and without it; each layer in its own process, {rounds} rounds "
        "taking turns "
        f"(median); {os.cpu_count()} cores; cloth_sim's default: NUMBA_THREADING_LAYER=forksafe"
    )
    print(
        "| layer | fork-safe | ms/step, steady | ms/step, 1/60 s ticks | without strain limit: "
        "steady | ticks | state hashes |"
    )
    print("|---|---|---|---|---|---|---|")
    results = measure(size, seconds, rounds)
    for layer, runs in results.items():
        safe = "no (GNU OpenMP)" if layer == "omp" else "yes"
        if isinstance(runs, str):
            print(f"| {layer} | {safe} | not available: {runs} | | | | |")
            continue
        cells = [
            f"{statistics.median(r[k] for r in runs):.3f}"
            for k in ("scene_steady_ms", "scene_ticks_ms", "free_steady_ms", "free_ticks_ms")
        ]
        hashes = ", ".join(
            sorted({r["scene_hash"] for r in runs} | {r["free_hash"] for r in runs})
        )
        print(f"| {layer} | {safe} | {' | '.join(cells)} | {hashes} |", flush=True)
    return results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="cloth-sim bench threading", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--child", nargs=2, metavar=("SIZE", "SECONDS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(_child(int(args.child[0]), float(args.child[1]))))
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
