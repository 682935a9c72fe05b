"""LeRobot's dataset format, v3.0, written with pyarrow and PyAV (LeRobot itself not needed).

The layout (LeRobot's ``lerobot/datasets/utils.py`` names the paths; its v3.0 documentation the
meaning), under the dataset's root:

* ``meta/info.json`` — the codebase version ``v3.0``, ``fps``, the features (dtype, shape, names;
  a video's encoding under ``info``), the totals and the path templates.
* ``data/chunk-CCC/file-FFF.parquet`` — the frames: a column a feature (``video`` features are not
  there), plus ``timestamp``, ``frame_index``, ``episode_index``, ``index`` (over the dataset) and
  ``task_index``.
* ``videos/<key>/chunk-CCC/file-FFF.mp4`` — each camera's frames as video.
* ``meta/episodes/chunk-CCC/file-FFF.parquet`` — a row an episode: its tasks, length, where its
  frames are (``data/…``, ``dataset_from_index``/``dataset_to_index``, ``videos/<key>/…`` with the
  episode's ``from_timestamp``/``to_timestamp`` in the file) and its statistics (``stats/<feature>/
  <min|max|mean|std|count|q01|q10|q50|q90|q99>``).
* ``meta/stats.json`` — the statistics over every episode (LeRobot's aggregation: counts weigh the
  means, quantiles and variances); images per channel, in ``[0, 1]``, shaped ``(3, 1, 1)``.
* ``meta/tasks.parquet`` — the task strings (the index, as pandas writes it) and their
  ``task_index``.

**Commits.** An episode is one file of each kind (``file-FFF`` is the episode's number within its
chunk of :data:`CHUNK` files), each written aside and renamed into place; ``meta/info.json`` is
written last, the same way, and is the record of what is committed: a dataset whose writer was
killed, or whose disk filled, mid-episode holds its committed episodes intact, and
:meth:`Writer.open` drops what a later episode left behind. Files hold one episode each so that
appending never rewrites a committed file, and so that the bytes of every file depend on its
episode alone (and the frames before it, for ``index``).
"""

from __future__ import annotations

import errno
import io
import json
import os
from fractions import Fraction
from pathlib import Path

import numpy as np

CODEBASE_VERSION = "v3.0"
#: files a chunk (LeRobot's DEFAULT_CHUNK_SIZE)
CHUNK = 1000
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
#: the columns every frame has beside the features (LeRobot's DEFAULT_FEATURES)
DEFAULT_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}
#: the video codec: H.264 at a fixed quality, every other frame a key frame (LeRobot's ``g=2``:
#: random access for training), one encoder thread (the same bytes on any machine count)
VIDEO = dict(codec="libx264", pix_fmt="yuv420p", options={"crf": "23", "g": "2", "threads": "1"})


class DatasetError(ValueError):
    """A dataset that cannot be written or resumed as asked; the message says what to do."""


def video_feature(height: int, width: int, fps: float, depth_range: tuple | None = None) -> dict:
    """A ``video`` feature's entry in ``info.json``; ``depth_range`` ``(near, far)`` (m) marks a
    depth map, stored as grey levels from ``near`` (0) to ``far`` (255)."""
    info = {
        "video.height": height,
        "video.width": width,
        "video.codec": "h264",
        "video.pix_fmt": VIDEO["pix_fmt"],
        "video.is_depth_map": depth_range is not None,
        "video.fps": fps,
        "video.channels": 3,
        "has_audio": False,
    }
    if depth_range is not None:
        info["video.depth_range_m"] = [float(depth_range[0]), float(depth_range[1])]
    return {
        "dtype": "video",
        "shape": [height, width, 3],
        "names": ["height", "width", "channels"],
        "info": info,
    }


def encode_video(frames: np.ndarray, fps: float) -> bytes:
    """``frames`` (``T × H × W × 3`` uint8) as an MP4 of :data:`VIDEO`'s codec at ``fps``."""
    import av

    frames = np.ascontiguousarray(frames, dtype=np.uint8)
    buf = io.BytesIO()
    with av.open(buf, "w", format="mp4") as out:
        stream = out.add_stream(
            VIDEO["codec"], rate=Fraction(fps).limit_denominator(1000), options=VIDEO["options"]
        )
        stream.pix_fmt = VIDEO["pix_fmt"]
        stream.height, stream.width = frames.shape[1:3]
        for image in frames:
            out.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        out.mux(stream.encode())
    return buf.getvalue()


def feature_stats(values: np.ndarray, image: bool = False) -> dict[str, np.ndarray]:
    """LeRobot's statistics of one feature over one episode: ``min``, ``max``, ``mean``, ``std``,
    ``count`` and the quantiles of :data:`QUANTILES` over the frames, per component; an image's
    (``T × H × W × 3`` uint8) per channel in ``[0, 1]``, shaped ``(3, 1, 1)``."""
    if image:
        x = np.asarray(values, np.float64).reshape(-1, values.shape[-1]) / 255.0
        shape = (values.shape[-1], 1, 1)
    else:
        x = np.asarray(values, np.float64).reshape(len(values), -1)
        shape = np.shape(values)[1:] or (1,)
    stats = {
        "min": x.min(axis=0),
        "max": x.max(axis=0),
        "mean": x.mean(axis=0),
        "std": x.std(axis=0),
    }
    for q in QUANTILES:
        stats[f"q{round(q * 100):02d}"] = np.quantile(x, q, axis=0)
    stats = {k: v.reshape(shape) for k, v in stats.items()}
    stats["count"] = np.array([len(values)], np.int64)
    return stats


def aggregate(stats: list[dict]) -> dict[str, np.ndarray]:
    """One feature's statistics over several episodes (LeRobot's ``aggregate_feature_stats``)."""
    counts = np.array([s["count"][0] for s in stats], np.float64)
    total = counts.sum()
    w = counts.reshape(-1, *[1] * np.ndim(stats[0]["mean"]))
    means = np.stack([s["mean"] for s in stats])
    mean = (means * w).sum(axis=0) / total
    var = ((np.stack([s["std"] for s in stats]) ** 2 + (means - mean) ** 2) * w).sum(0) / total
    out = {
        "min": np.min([s["min"] for s in stats], axis=0),
        "max": np.max([s["max"] for s in stats], axis=0),
        "mean": mean,
        "std": np.sqrt(var),
        "count": np.array([int(total)], np.int64),
    }
    for q in QUANTILES:
        key = f"q{round(q * 100):02d}"
        out[key] = (np.stack([s[key] for s in stats]) * w).sum(axis=0) / total
    return out


def _replace(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` aside, then rename it into place (the tmp file removed if the
    write fails)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _parquet(table) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="snappy")
    return sink.getvalue().to_pybytes()


def _locate(episode: int) -> dict:
    return dict(chunk_index=episode // CHUNK, file_index=episode % CHUNK)


class Writer:
    """Appends episodes to the dataset at ``root`` (see the module docstring).

    ``features``: the frame features (``observation.state``, ``action``, …, videos), as
    ``info.json`` has them; :data:`DEFAULT_FEATURES` are added."""

    def __init__(self, root, features: dict, fps: float, robot_type: str | None = None):
        self.root = Path(root)
        self.info = {
            "codebase_version": CODEBASE_VERSION,
            "robot_type": robot_type,
            "total_episodes": 0,
            "total_frames": 0,
            "total_tasks": 0,
            "chunks_size": CHUNK,
            "data_files_size_in_mb": 100,
            "video_files_size_in_mb": 200,
            "fps": fps,
            "splits": {},
            "data_path": DATA_PATH,
            "video_path": VIDEO_PATH,
            "features": {**features, **DEFAULT_FEATURES},
        }
        self.tasks: list[str] = []
        self.stats: dict[str, list[dict]] = {}

    @property
    def episodes(self) -> int:
        return self.info["total_episodes"]

    @property
    def video_keys(self) -> list[str]:
        return [k for k, f in self.info["features"].items() if f["dtype"] == "video"]

    @classmethod
    def open(cls, root) -> Writer:
        """The dataset at ``root`` as committed, files past its last committed episode removed."""
        import pyarrow.parquet as pq

        root = Path(root)
        info = json.loads((root / "meta" / "info.json").read_text())
        if info.get("codebase_version") != CODEBASE_VERSION:
            raise DatasetError(
                f"{root}: a LeRobot dataset of codebase_version "
                f"{info.get('codebase_version')!r}; this writes {CODEBASE_VERSION}"
            )
        w = cls.__new__(cls)
        w.root, w.info = root, info
        n = info["total_episodes"]
        tasks = root / "meta" / "tasks.parquet"
        w.tasks = []
        if tasks.exists():
            table = pq.read_table(tasks)
            order = np.argsort(table.column("task_index").to_numpy())
            w.tasks = [table.column("__index_level_0__").to_pylist()[i] for i in order]
        w.stats = {}
        for e in range(n):
            (row,) = pq.read_table(root / EPISODES_PATH.format(**_locate(e))).to_pylist()
            per: dict[str, dict] = {}
            for key, value in row.items():
                if key.startswith("stats/"):
                    _, feature, stat = key.split("/")
                    per.setdefault(feature, {})[stat] = np.array(value)
            for feature, s in per.items():
                w.stats.setdefault(feature, []).append(s)
        w._drop_after(n)
        w.tasks = w.tasks[: info["total_tasks"]]
        if n:  # a commit that died after these and before info.json: back to the committed ones
            w._summaries(w.tasks, w.stats)
        return w

    def _summaries(self, tasks: list[str], stats: dict, rewrite_tasks: bool = True) -> None:
        """``meta/tasks.parquet`` and ``meta/stats.json`` for these tasks and episodes' stats."""
        if rewrite_tasks:
            _replace(self.root / "meta" / "tasks.parquet", _parquet(_tasks_table(tasks)))
        summary = {
            k: {s: v.tolist() for s, v in aggregate(lst).items()} for k, lst in stats.items()
        }
        _replace(self.root / "meta" / "stats.json", json.dumps(summary, indent=4).encode())

    def _drop_after(self, n: int) -> None:
        """Remove the files of episodes ``>= n`` (and ``*.tmp`` files) a killed commit left."""
        for base in ("data", "meta/episodes"):
            self._drop(self.root / base, n)
        for key in self.video_keys:
            self._drop(self.root / "videos" / key, n)

    @staticmethod
    def _drop(base: Path, n: int) -> None:
        if not base.is_dir():
            return
        for path in base.glob("chunk-*/file-*"):
            chunk = int(path.parent.name.split("-")[1])
            stem = path.name.split(".")[0]
            if path.name.endswith(".tmp") or chunk * CHUNK + int(stem.split("-")[1]) >= n:
                path.unlink()

    def write_episode(
        self, frames: dict, videos: dict, task: str, extra: dict | None = None
    ) -> int:
        """Commit one episode: ``frames`` maps each non-video feature to an array with a row a
        frame; ``videos`` maps each video feature to ``(encoded MP4 bytes, its statistics)``
        (:func:`feature_stats` of its frames). Returns the episode's index. An ``OSError`` (a full
        disk) leaves the dataset as it was before the call."""
        import pyarrow as pa

        e = self.episodes
        length = len(next(iter(frames.values())))
        fps = self.info["fps"]
        start = self.info["total_frames"]
        new_task = task not in self.tasks
        task_index = self.tasks.index(task) if not new_task else len(self.tasks)
        columns = dict(frames)
        columns["timestamp"] = (np.arange(length) / fps).astype(np.float32)
        columns["frame_index"] = np.arange(length, dtype=np.int64)
        columns["episode_index"] = np.full(length, e, np.int64)
        columns["index"] = np.arange(start, start + length, dtype=np.int64)
        columns["task_index"] = np.full(length, task_index, np.int64)
        features = self.info["features"]
        missing = {k for k, f in features.items() if f["dtype"] != "video"} - set(columns)
        if missing or set(videos) != set(self.video_keys):
            raise ValueError(f"episode {e}: features missing: {sorted(missing)}")
        arrays, stats = {}, {}
        for key, ft in features.items():
            if ft["dtype"] == "video":
                stats[key] = videos[key][1]
                continue
            values = np.asarray(columns[key])
            if values.dtype.kind == "b":
                arrays[key] = pa.array(values)
            elif values.ndim == 1:
                arrays[key] = pa.array(values.astype(ft["dtype"]))
            else:
                arrays[key] = _fixed_list(values.astype(ft["dtype"]))
            stats[key] = feature_stats(values)  # (as float64: booleans too)
        where = _locate(e)
        row = {
            "episode_index": e,
            "tasks": [task],
            "length": length,
            "data/chunk_index": where["chunk_index"],
            "data/file_index": where["file_index"],
            "dataset_from_index": start,
            "dataset_to_index": start + length,
        }
        for key in self.video_keys:
            row[f"videos/{key}/chunk_index"] = where["chunk_index"]
            row[f"videos/{key}/file_index"] = where["file_index"]
            row[f"videos/{key}/from_timestamp"] = 0.0
            row[f"videos/{key}/to_timestamp"] = length / fps
        row.update(extra or {})
        row["meta/episodes/chunk_index"] = where["chunk_index"]
        row["meta/episodes/file_index"] = where["file_index"]
        for key, s in stats.items():
            for stat, value in s.items():
                row[f"stats/{key}/{stat}"] = value.tolist()

        written = [self.root / DATA_PATH.format(**where)]
        written += [self.root / VIDEO_PATH.format(video_key=k, **where) for k in self.video_keys]
        written.append(self.root / EPISODES_PATH.format(**where))
        try:
            _replace(written[0], _parquet(pa.table(arrays)))
            for key, path in zip(self.video_keys, written[1:-1]):
                _replace(path, videos[key][0])
            _replace(written[-1], _parquet(pa.Table.from_pylist([row])))
            tasks = self.tasks + [task] if new_task else self.tasks
            all_stats = {k: self.stats.get(k, []) + [s] for k, s in stats.items()}
            self._summaries(tasks, all_stats, rewrite_tasks=new_task)
            info = dict(
                self.info,
                total_episodes=e + 1,
                total_frames=start + length,
                total_tasks=len(tasks),
                splits={"train": f"0:{e + 1}"},
            )
            _replace(self.root / "meta" / "info.json", json.dumps(info, indent=4).encode())
        except OSError:
            for path in written:  # a new episode's files, never a committed one's
                path.unlink(missing_ok=True)
            raise
        self.info, self.tasks, self.stats = info, tasks, all_stats
        return e


def _fixed_list(values: np.ndarray):
    """A fixed-size list column (``datasets``' Sequence/Array of the feature's shape)."""
    import pyarrow as pa

    arr = pa.array(values.reshape(-1))
    for size in reversed(values.shape[1:]):
        arr = pa.FixedSizeListArray.from_arrays(arr, size)
    return arr


def _tasks_table(tasks: list[str]):
    """``meta/tasks.parquet`` as pandas writes a frame indexed by the task strings (so that
    LeRobot's ``pd.read_parquet`` gets the index back)."""
    import pyarrow as pa

    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": None,
                "field_name": "__index_level_0__",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }
    table = pa.table(
        {
            "task_index": pa.array(range(len(tasks)), pa.int64()),
            "__index_level_0__": pa.array(tasks, pa.string()),
        }
    )
    return table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})


def is_full(error: OSError) -> bool:
    """Whether ``error`` is a full disk (or quota)."""
    return error.errno in (errno.ENOSPC, errno.EDQUOT)
