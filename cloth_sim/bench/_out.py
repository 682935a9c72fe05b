"""Shared output helpers of the benchmarks: CSV/JSON/Markdown files, plots, progress bars, machine
line."""

from __future__ import annotations

import csv
import json
import os
import platform
from pathlib import Path

from ..model import ClothModel

G = (0.0, 0.0, -9.81)


def hang16(k: float = 1000.0, damping: float = 0.0) -> ClothModel:
    """Scene hang16: 16×16 grid, 1 m square, k for every family, 0.01 kg particles, two corners of
    one edge pinned, flat and at rest (no wind, no strain limit are the simulator's defaults)."""
    return ClothModel.grid(
        16, 16, 1.0 / 15, 0.01, stiffness=k, damping=damping, pinned=[(0, 0), (0, 15)]
    )


def machine() -> str:
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{cpu or platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', '-')}"
    )


def progress(iterable, desc: str, total: int | None = None):
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False, disable=None)


def write_rows(out: Path, stem: str, rows: list[dict], extra: dict | None = None) -> None:
    """``stem.csv`` (one row per dict) and ``stem.json`` (rows plus ``extra``)."""
    out.mkdir(parents=True, exist_ok=True)
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    doc = _strict({"machine": machine(), **(extra or {}), "rows": rows})
    (out / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=float, allow_nan=False))


def _strict(value):
    """Standard JSON has no NaN or infinity: NaN (not applicable, failed run) becomes null and an
    infinite value (no stability limit) the string "inf"."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, float) or type(value).__module__ == "numpy":
        try:
            x = float(value)
        except (TypeError, ValueError):
            return value
        if x != x:
            return None
        if x in (float("inf"), float("-inf")):
            return "inf" if x > 0 else "-inf"
        return x if isinstance(value, float) else value.item()
    return value


def markdown_table(headers: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fmt(x, digits=3) -> str:
    if x is None or x != x:
        return "–"
    if x == float("inf"):
        return "∞"
    return f"{x:.{digits}g}"
