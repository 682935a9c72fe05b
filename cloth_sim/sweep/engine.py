"""The sweep's driver: every run of a spec on Ray, resumable, with a progress bar and
``runs.parquet``.

``cloth-sim sweep SPEC.yaml -o OUT [--workers N] [--address ADDRESS]``:

* Ray is started on this machine (``--workers`` CPUs, default all) unless ``--address`` names a
  running cluster (``ray start --head`` / KubeRay); each run is one Ray task of one CPU
  (:func:`cloth_sim.sweep.run.execute`), at most ``2 × workers`` in flight, so the driver's memory
  does not grow with the number of runs. Runs that Ray loses with a worker are retried by Ray.
* ``OUT`` must be a path every worker can write and the driver read: a local directory, or a shared
  file system (NFS, a mounted bucket) on a cluster. A run commits by renaming its directory, which
  object stores do not offer, so ``s3://`` and the like are refused.
* ``OUT/spec.yaml`` keeps the spec; the same command again resumes: runs with a committed directory
  are skipped, half-written ones (``OUT/.partial``) are dropped and run again. A different spec in
  the same ``OUT`` is refused.
* At the end ``OUT/runs.parquet`` is written (atomically) from the runs' rows, in the spec's order.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from collections import Counter
from pathlib import Path

from . import cluster
from .run import STATUSES, execute, read_row
from .spec import Spec, SpecError, load_spec, run_id

#: the columns of runs.parquet after the swept values
RESULT_COLUMNS = (
    "status",
    "message",
    "wall_s",
    "steps",
    "sim_time",
    "max_strain",
    "kinetic",
    "potential",
    "stable_dt",
    "frames",
    "worker",
)
#: rows per Parquet row group (and per batch read while writing it)
BATCH = 1000


def canonical(spec: Spec) -> str:
    """What makes two specs the same sweep (not their comments or key order)."""
    return json.dumps(
        {
            "scene": spec.scene,
            "duration": spec.duration,
            "frames": spec.frames,
            "seed": spec.seed,
            "set": spec.fixed,
            "grid": spec.grid,
            "random": spec.random,
            "samples": spec.samples,
            "script": spec.script,
        },
        sort_keys=True,
    )


def prepare(spec: Spec, out: Path) -> set[str]:
    """Make ``out`` (or check that it holds this spec), drop half-written runs; the ids done."""
    if "://" in str(out):
        raise SpecError(
            f"-o {out}: object-store URLs are not supported (a run commits by renaming "
            f"its directory); use a local or shared (NFS) path"
        )
    if out.exists() and not out.is_dir():
        raise SpecError(f"-o {out}: exists and is not a directory")
    marker = out / "sweep.json"
    if out.exists() and any(out.iterdir()):
        if not marker.exists():
            raise SpecError(
                f"-o {out}: exists and holds no sweep; choose a new or empty directory"
            )
        if json.loads(marker.read_text())["spec"] != json.loads(canonical(spec)):
            raise SpecError(
                f"-o {out}: holds a sweep of another spec ({out / 'spec.yaml'}); "
                f"choose another directory to run this one"
            )
    (out / "runs").mkdir(parents=True, exist_ok=True)
    if not marker.exists():
        (out / "spec.yaml").write_text(spec.text or "")
        tmp = marker.with_suffix(".tmp")
        tmp.write_text(json.dumps({"spec": json.loads(canonical(spec)), "runs": len(spec)}))
        os.replace(tmp, marker)
    shutil.rmtree(out / ".partial", ignore_errors=True)
    return {d.name for d in (out / "runs").iterdir() if (d / "row.json").exists()}


def _remote_execute(spec, run, out):
    return execute(spec, run, out)


def sweep(
    spec_path, out, workers: int | None = None, address: str | None = None, progress: bool = True
) -> Counter:
    """Run every run of the spec at ``spec_path`` not yet in ``out``; returns the counts by status
    of all the sweep's runs. :class:`SpecError` for a bad spec or output, before anything runs."""
    spec = load_spec(spec_path)
    out = Path(out)
    if workers is not None and workers < 1:
        raise SpecError(f"--workers {workers}: must be at least 1")
    done = prepare(spec, out)
    counts: Counter = Counter()
    for rid in done:
        counts[read_row(out / "runs" / rid)["status"]] += 1
    pending = (run for run in spec.runs() if run_id(run) not in done)
    if len(done) < len(spec):
        _run_on_ray(spec, out, pending, len(spec), counts, workers, address, progress)
    write_parquet(spec, out)
    try:
        (out / ".partial").rmdir()  # empty once every run is committed
    except OSError:
        pass
    return counts


def _run_on_ray(spec, out, pending, total, counts, workers, address, progress) -> None:
    import ray
    from tqdm import tqdm

    with cluster.session(workers, address, SpecError) as workers:
        task = ray.remote(num_cpus=1, max_retries=3)(_remote_execute)
        spec_ref = ray.put(spec)
        out_s = str(out.resolve())
        bar = tqdm(
            total=total,
            initial=sum(counts.values()),
            unit="run",
            disable=not progress,
            file=sys.stderr,
            dynamic_ncols=True,
            smoothing=0.05,
        )
        bar.set_postfix(_postfix(counts), refresh=False)
        in_flight = []
        exhausted = False
        while True:
            while not exhausted and len(in_flight) < 2 * workers:
                run = next(pending, None)
                if run is None:
                    exhausted = True
                    break
                in_flight.append(task.remote(spec_ref, run, out_s))
            if not in_flight:
                break
            ready, in_flight = ray.wait(in_flight, num_returns=1)
            for ref in ready:
                row = ray.get(ref)
                counts[row["status"]] += 1
                bar.update(1)
                bar.set_postfix(_postfix(counts), refresh=False)
        bar.close()


def _postfix(counts: Counter) -> dict:
    return {
        "unstable": counts["unstable"],
        "diverged": counts["diverged"],
        "refused": counts["refused"],
        **({"failed": counts["failed"]} if counts["failed"] else {}),
    }


def _columns(spec: Spec) -> list[str]:
    return ["run", *spec.swept, *(["sample"] if spec.random else []), *RESULT_COLUMNS]


def write_parquet(spec: Spec, out: Path) -> Path:
    """``OUT/runs.parquet`` from every run's ``row.json`` in the spec's order, a row group of
    :data:`BATCH` rows at a time (written aside, then renamed)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = _columns(spec)
    schema = None
    path, tmp = out / "runs.parquet", out / "runs.parquet.tmp"
    writer = None
    try:
        batch: list[dict] = []

        def flush():
            nonlocal writer, schema
            table = pa.Table.from_pylist(
                [{c: r.get(c) for c in columns} for r in batch], schema=schema
            )
            if writer is None:
                schema = table.schema
                writer = pq.ParquetWriter(tmp, schema)
            writer.write_table(table)
            batch.clear()

        for run in spec.runs():
            batch.append(read_row(out / "runs" / run_id(run)))
            if len(batch) >= BATCH:
                flush()
        if batch or writer is None:
            flush()
    finally:
        if writer is not None:
            writer.close()
    os.replace(tmp, path)
    return path


def summary(out) -> str:
    """Counts by status and the slowest runs of the sweep in ``out`` (from ``runs.parquet``, or
    the committed runs' rows while it is incomplete)."""
    out = Path(out)
    marker = out / "sweep.json"
    if not marker.exists():
        raise SpecError(f"{out}: holds no sweep (no sweep.json)")
    total = json.loads(marker.read_text())["runs"]
    if (out / "runs.parquet").exists():
        import pyarrow.parquet as pq

        rows = pq.read_table(out / "runs.parquet").to_pylist()
        state = "complete"
    else:
        rows = [read_row(d) for d in sorted((out / "runs").iterdir()) if (d / "row.json").exists()]
        state = (
            f"incomplete: {len(rows)} of {total} runs done; run the same command again to finish"
        )
    counts = Counter(r["status"] for r in rows)
    lines = [f"sweep {out}: {total} runs ({state})"]
    lines += [
        f"  {s:9s} {counts[s]}"
        for s in STATUSES
        if counts[s] or s in ("ok", "unstable", "diverged", "refused")
    ]
    wall = sum(r["wall_s"] for r in rows)
    lines.append(f"  run time {wall:.1f} s in all, {wall / max(len(rows), 1):.3f} s per run")
    slow = sorted(rows, key=lambda r: -r["wall_s"])[:5]
    if slow:
        lines.append("slowest runs:")
        skip = {"run", "message", *RESULT_COLUMNS}
        for r in slow:
            values = ", ".join(f"{k}={_fmt(v)}" for k, v in r.items() if k not in skip)
            lines.append(f"  {r['run']}  {r['wall_s']:.3f} s  {r['status']:8s}  {values}")
    return "\n".join(lines)


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)
