"""One run of a sweep, headless (no ROS graph): build the simulation from the base scene and the
run's values exactly as the node would (:func:`cloth_sim.settings.configure`), play the script,
write a bag of its frames, and commit the run's directory whole.

Files: the run is written under ``OUT/.partial/<token>/<run>/`` — the bag (``<run>_0.mcap``,
``metadata.yaml``) and ``row.json`` (the run's row of ``runs.parquet`` but its wall time, which
goes to ``OUT/timings/<run>.json`` first) — and the directory is then renamed to
``OUT/runs/<run>/`` in one step, so ``runs/`` only ever holds whole runs. A run that finds its
directory there already (another worker did it after a restart) drops its own copy: the bytes are
the same.

Bags hold ``/cloth_sim/points`` and ``/cloth_sim/stats`` as the node publishes them (and, with
``camera.enable``, the camera's image, camera info, labels and triangles), stamped with simulated
time, written by :mod:`cloth_sim.bag.cdr` so that a run's bytes depend on its values alone: the
wall-clock fields of ``Stats`` (``step_time_mean``, ``step_time_max``, ``tick_wall_time``,
``real_time_factor``) are 0 in a sweep's bags — a run's timings are in ``runs.parquet``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time
import uuid
from pathlib import Path

from .. import settings
from ..bag import cdr
from ..bag.store import BagWriter
from ..physics.energy_balance import EnergyBalance
from ..simulator import SimulationDiverged
from ..tick_stats import TickStats, stability_margin
from .script import Script, ScriptError
from .spec import Spec, resolve, run_id

#: a run's fate: ``unstable`` is a run that stayed finite but holds energy no source put in
#: (:mod:`cloth_sim.physics.energy_balance`): a step past its limit that chatters instead of
#: blowing up
STATUSES = ("ok", "unstable", "diverged", "refused", "failed")
#: what a run measures rather than computes: kept beside its directory
#: (``OUT/timings/<run>.json``),
#: so that the directory's bytes depend on the run's values alone
TIMINGS = ("wall_s", "worker")
#: the QoS the node offers on its topics (reliable, volatile, keep last 10; the camera's 5)
_QOS = {
    "history": "keep_last",
    "depth": 10,
    "reliability": "reliable",
    "durability": "volatile",
    "deadline": {"sec": 0, "nsec": 0},
    "lifespan": {"sec": 0, "nsec": 0},
    "liveliness": "automatic",
    "liveliness_lease_duration": {"sec": 0, "nsec": 0},
    "avoid_ros_namespace_conventions": False,
}


def execute(spec: Spec, run: dict, out) -> dict:
    """Run ``run`` (one of ``spec.runs()``) and commit ``OUT/runs/<run>/``; returns its row.
    Never raises for the run's own sake: a refused, diverged or failed run is a row."""
    out = Path(out)
    rid = run_id(run)
    final = out / "runs" / rid
    if (final / "row.json").exists():
        return read_row(final)
    tmp = out / ".partial" / uuid.uuid4().hex / rid
    tmp.parent.mkdir(parents=True)
    try:
        row = simulate(spec, run, rid, tmp)  # (the bag makes the directory)
        tmp.mkdir(exist_ok=True)
        kept = {k: v for k, v in row.items() if k not in TIMINGS}
        (tmp / "row.json").write_text(json.dumps(kept, sort_keys=True, allow_nan=True))
        timing = out / "timings" / f"{rid}.json"  # first: a committed run always has its timing
        timing.parent.mkdir(exist_ok=True)
        timing.with_suffix(".tmp").write_text(json.dumps({k: row[k] for k in TIMINGS}))
        os.replace(timing.with_suffix(".tmp"), timing)
        final.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(tmp, final)
        except OSError:
            if not (final / "row.json").exists():
                raise
        return row
    finally:
        shutil.rmtree(tmp.parent, ignore_errors=True)


def simulate(spec: Spec, run: dict, rid: str, tmp: Path | None, recorder=None) -> dict:
    """The run, its frames to the bag in ``tmp`` (none when the spec has ``frames: 0``), or to
    ``recorder(sim, cfg)``'s ``frame(sim)`` (and ``close()``) instead; returns its row."""
    t0 = time.perf_counter()
    params, variables = spec.values_for(run)
    row = {
        "run": rid,
        **run,
        "status": "ok",
        "message": "",
        "wall_s": 0.0,
        "steps": 0,
        "sim_time": 0.0,
        "max_strain": math.nan,
        "kinetic": math.nan,
        "potential": math.nan,
        "stable_dt": math.nan,
        "frames": 0,
        "worker": _worker(),
    }
    try:
        cfg, scene, sim, stable_dt = settings.configure(params.get("scene", spec.scene), params)
    except ValueError as e:
        row.update(
            status="refused", message=str(e), wall_s=time.perf_counter() - t0, worker=_worker()
        )
        return row
    row["stable_dt"] = float(stable_dt)
    script = Script([resolve(e, variables) for e in spec.script])
    if recorder is not None:
        bag = recorder(sim, cfg)
    else:
        bag = _Bag(tmp, sim, cfg, stable_dt) if spec.frames > 0 else None
    n_steps = max(0, math.ceil(spec.duration / sim.dt - 1e-9))
    # frame k at the first step at or after k/frames
    frame_times = (
        [k / spec.frames for k in range(int(math.floor(spec.duration * spec.frames + 1e-9)) + 1)]
        if bag
        else []
    )
    next_frame = 0
    balance = EnergyBalance(sim)
    try:
        for _ in range(n_steps):
            while next_frame < len(frame_times) and frame_times[next_frame] <= sim.time + 1e-12:
                bag.frame(sim)
                next_frame += 1
            script.before_step(sim)
            sim.step(1)
            balance.sample()
        while next_frame < len(frame_times) and frame_times[next_frame] <= sim.time + 1e-9:
            bag.frame(sim)
            next_frame += 1
    except SimulationDiverged as e:
        row.update(status="diverged", message=str(e))
    except ScriptError as e:
        row.update(status="refused", message=str(e))
    except Exception as e:  # a defect, not the run's values: recorded, the sweep goes on
        row.update(status="failed", message=f"{type(e).__name__}: {e}")
    finally:
        if bag is not None:
            row["frames"] = bag.close()
    if row["status"] == "ok" and balance.unstable:
        row.update(status="unstable", message=balance.message())
    energy = sim.energy()
    row.update(
        steps=int(sim.steps_taken),
        sim_time=float(sim.time),
        max_strain=float(sim.max_strain()),
        kinetic=float(energy["kinetic"]),
        potential=float(energy["spring"] + energy["gravity"]),
        wall_s=time.perf_counter() - t0,
    )
    return row


def _worker() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


class _Bag:
    """A run's bag: its topics and one frame at a time."""

    def __init__(self, path: Path, sim, cfg: dict, stable_dt: float):
        self.writer = BagWriter(path)
        dt = sim.dt
        self.margin = stability_margin(dt, stable_dt)
        self.frame_id = cfg["frame_id"]
        self.cfg = cfg
        self.points = self.writer.add_topic(
            "/cloth_sim/points", "sensor_msgs/msg/PointCloud2", [_QOS]
        )
        self.stats = self.writer.add_topic("/cloth_sim/stats", "cloth_sim/msg/Stats", [_QOS])
        self.camera = None
        if cfg["camera.enable"]:
            from ..sensors.camera import camera_from_settings

            self.camera = camera_from_settings(settings.camera_settings(cfg))
            qos = [dict(_QOS, depth=5)]
            self.cam_topics = {
                name: self.writer.add_topic(f"/cloth_sim/camera/{name}", kind, qos)
                for name, kind in (
                    ("depth/image", "sensor_msgs/msg/Image"),
                    ("depth/camera_info", "sensor_msgs/msg/CameraInfo"),
                    ("labels", "sensor_msgs/msg/Image"),
                    ("triangles", "sensor_msgs/msg/Image"),
                )
            }
            self.optical = f"{self.frame_id}/camera_optical"
        model = sim.model
        self.shape = (model.rows, model.cols) if model.rows else (1, model.n_particles)
        self.last_steps = 0
        self.count = 0

    def frame(self, sim) -> None:
        t = int(round(sim.time * 1e9))
        w = self.writer
        w.write(self.points, t, cdr.point_cloud(sim.positions, *self.shape, self.frame_id, t))
        tick = TickStats.of(
            sim, steps=sim.steps_taken - self.last_steps, stability_margin=self.margin
        )
        w.write(self.stats, t, cdr.stats(t, self.frame_id, tick))
        self.last_steps = sim.steps_taken
        if self.camera is not None:
            f = self.camera.render(sim)
            topics, optical = self.cam_topics, self.optical
            w.write(topics["depth/image"], t, cdr.image(f.depth, "32FC1", optical, t))
            w.write(topics["depth/camera_info"], t, cdr.camera_info(self.camera, optical, t))
            w.write(topics["labels"], t, cdr.image(f.object, "16SC1", optical, t))
            w.write(topics["triangles"], t, cdr.image(f.triangle, "32SC1", optical, t))
        self.count += 1

    def close(self) -> int:
        self.writer.close()
        return self.count


def read_row(run_dir) -> dict:
    """A committed run's row: ``row.json`` and its timing (``OUT/timings/<run>.json``; NaN if
    lost)."""
    run_dir = Path(run_dir)
    row = json.loads((run_dir / "row.json").read_text())
    try:
        row.update(
            json.loads((run_dir.parent.parent / "timings" / f"{run_dir.name}.json").read_text())
        )
    except (OSError, ValueError):
        row.update(wall_s=math.nan, worker="")
    return row
