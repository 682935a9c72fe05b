"""Plot a stability-map sweep (docs/sweeps/stability_map.yaml) and check it against linear theory.

    .venv/bin/python docs/sweeps/plot_stability_map.py OUT [--png docs/sweeps/stability_map.png]

One panel per integrator: dt across, structural stiffness up; each run a green dot (ok) or a red
cross (diverged); the black steps are each stiffness's stable_dt, the limit the simulator computes
before any step (cloth_sim.physics.stability). Prints, per integrator, how many runs theory calls
right: ok below the limit, diverged above it.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--png", type=Path, default=Path(__file__).with_name("stability_map.png"))
    args = ap.parse_args()
    rows = pq.read_table(args.out / "runs.parquet").to_pylist()
    by = defaultdict(list)
    for r in rows:
        by[r["integrator"]].append(r)
    names = list(dict.fromkeys(r["integrator"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(3.2 * len(names), 3.4), sharey=True)
    print(
        "| integrator | runs | ok below stable_dt | diverged or unstable above | ok above "
        "(bounded in 1 s, "
        "energy balanced) | diverged or unstable below |"
    )
    print("|---|---|---|---|---|---|")
    for ax, name in zip(axes, names):
        rs = by[name]
        for status, style in (
            ("ok", dict(marker="o", color="tab:green", s=18)),
            ("unstable", dict(marker="^", color="tab:orange", s=22)),
            ("diverged", dict(marker="x", color="tab:red", s=28)),
        ):
            pts = [(r["dt"], r["stiffness.structural"]) for r in rs if r["status"] == status]
            if pts:
                ax.scatter(*zip(*pts), label=status, **style)
        limits = sorted({(r["stiffness.structural"], r["stable_dt"]) for r in rs})
        ax.step(
            [lim for _, lim in limits],
            [k for k, _ in limits],
            where="mid",
            color="k",
            lw=1,
            label="stable_dt",
        )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("dt (s)")
        below = [r for r in rs if r["dt"] <= r["stable_dt"]]
        above = [r for r in rs if r["dt"] > r["stable_dt"]]
        print(
            f"| {name} | {len(rs)} | {sum(r['status'] == 'ok' for r in below)} of {len(below)} | "
            f"{sum(r['status'] in ('diverged', 'unstable') for r in above)} of {len(above)} | "
            f"{sum(r['status'] == 'ok' for r in above)} | "
            f"{sum(r['status'] in ('diverged', 'unstable') for r in below)} |"
        )
    axes[0].set_ylabel("stiffness.structural (N/m)")
    axes[-1].legend(fontsize=7, loc="lower left")
    fig.suptitle(
        "16×16 hanging cloth, 1 s: ok (bounded, energy balanced), unstable (bounded, energy "
        "no source put in) or diverged",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)
    print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
