"""``cloth-sim dataset TASK -o DIR``: episodes of a task under a policy, made on Ray, written as a
LeRobotDataset v3.0 (:mod:`.lerobot`) in episode order.

* Each episode is one Ray task of one CPU (:func:`.rollout.episode`: the env made once a worker),
  at most ``2 × workers`` in flight; the driver commits them in order as they come back, so the
  files are the same bytes at any worker count.
* ``DIR/meta/cloth_sim.json`` keeps what made the dataset (task, policy, observation, seed, image
  size). The same command again resumes after the last committed episode (a larger
  ``--episodes`` extends it); a ``DIR`` holding another dataset is refused unless ``--overwrite``
  (which removes it first); a ``DIR`` holding anything else is always refused.
* A full disk stops the run with the episodes committed so far intact; free space and run the same
  command again.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

from ..sweep import cluster
from . import rollout
from .lerobot import DatasetError, Writer, is_full

MARKER = "meta/cloth_sim.json"
_ENVS: dict = {}


def _env(config: dict):
    key = json.dumps(config, sort_keys=True)
    if key not in _ENVS:
        _ENVS[key] = rollout.make_env(
            config["task"], config["observation"], config["image_size"], config.get("cache_dir")
        )
    return _ENVS[key]


def _remote_episode(config: dict, index: int) -> dict:
    return rollout.episode(_env(config), index, config["seed"], config["policy"])


def prepare(out: Path, recorded: dict, overwrite: bool) -> None:
    """Make ``out`` or check that it holds the dataset ``recorded`` (``meta/cloth_sim.json``'s
    contents) describes (see the module docstring)."""
    if "://" in str(out):
        raise DatasetError(f"-o {out}: object-store URLs are not supported; use a local path")
    if out.exists() and not out.is_dir():
        raise DatasetError(f"-o {out}: exists and is not a directory")
    if not out.exists() or not any(out.iterdir()):
        return
    marker, info = out / MARKER, out / "meta" / "info.json"
    mine = marker.exists() and json.loads(marker.read_text()) == recorded
    if mine and not overwrite:
        return
    if not marker.exists() and not info.exists():
        raise DatasetError(
            f"-o {out}: holds files that are not a LeRobot dataset; choose a new or empty "
            f"directory (--overwrite removes only a dataset)"
        )
    if not overwrite:
        what = (
            f"a dataset of another command ({json.loads(marker.read_text())})"
            if marker.exists()
            else "a LeRobot dataset that cloth-sim did not write"
        )
        raise DatasetError(
            f"-o {out}: holds {what}; choose another directory, or add --overwrite to replace it"
        )
    for child in out.iterdir():
        shutil.rmtree(child) if child.is_dir() else child.unlink()


def _recorded(config: dict) -> dict:
    """What ``meta/cloth_sim.json`` keeps: what the episodes' bytes depend on."""
    return {k: config[k] for k in ("task", "policy", "observation", "seed", "image_size")}


def generate(
    task: str,
    out,
    policy: str = "scripted",
    episodes: int = 50,
    observation: str = "key_point",
    seed: int = 0,
    workers: int | None = None,
    address: str | None = None,
    overwrite: bool = False,
    image_size: int = 128,
    progress: bool = True,
    cache_dir=None,
) -> Writer:
    """Write (or resume) the dataset; returns its writer (``.episodes`` committed). Bad input is
    a :class:`DatasetError` raised before anything is written."""
    out = Path(out)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise DatasetError(f"--episodes {episodes!r}: expected an integer >= 1")
    if workers is not None and workers < 1:
        raise DatasetError(f"--workers {workers}: must be at least 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise DatasetError(f"--seed {seed!r}: expected an integer >= 0")
    env = rollout.make_env(task, observation, image_size, cache_dir)
    rollout.check_policy(env, policy)
    config = dict(
        task=env.spec.id if env.spec else task,
        policy=policy,
        observation=observation,
        seed=seed,
        image_size=image_size,
    )
    prepare(out, _recorded(config), overwrite)
    if (out / "meta" / "info.json").exists():
        writer = Writer.open(out)
    else:
        writer = Writer(
            out, rollout.features(env, observation), rollout.fps(env), robot_type="cloth_sim"
        )
        (out / "meta").mkdir(parents=True, exist_ok=True)
        (out / MARKER).write_text(json.dumps(_recorded(config), indent=2))
    if writer.episodes < episodes:
        config["cache_dir"] = None if cache_dir is None else str(cache_dir)
        jobs = [(config, i) for i in range(episodes)]
        commit_in_order(writer, _remote_episode, jobs, writer.episodes, workers, address, progress)
    return writer


def commit_in_order(
    writer: Writer, fn, jobs: list, first: int, workers, address, progress
) -> None:
    """``fn(*jobs[k])`` on Ray for each job ``k`` from ``first`` on, each result (an episode:
    ``frames``, ``videos``, ``task``, ``extra``) committed in the jobs' order; a ``None`` result is
    a job that makes no episode (skipped)."""
    import ray
    from tqdm import tqdm

    with cluster.session(workers, address, DatasetError) as workers:
        task = ray.remote(num_cpus=1, max_retries=3)(fn)
        bar = tqdm(
            total=len(jobs),
            unit="episode",
            disable=not progress,
            file=sys.stderr,
            dynamic_ncols=True,
        )
        pending = iter(range(first, len(jobs)))
        bar.update(first)
        in_flight: dict = {}
        done: dict[int, dict | None] = {}
        following = first
        while True:
            while len(in_flight) < 2 * workers:
                i = next(pending, None)
                if i is None:
                    break
                in_flight[task.remote(*jobs[i])] = i
            if not in_flight:
                break
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in ready:
                done[in_flight.pop(ref)] = ray.get(ref)
            while following in done:
                result = done.pop(following)
                following += 1
                bar.update(1)
                if result is None:
                    continue
                e = writer.episodes
                try:
                    writer.write_episode(
                        result["frames"], result["videos"], result["task"], result["extra"]
                    )
                except OSError as error:
                    if not is_full(error):
                        raise
                    raise DatasetError(
                        f"{writer.root}: the disk filled while writing episode {e} ({error}); "
                        f"the {e} episodes committed before it are intact: free space and run "
                        f"the same command again to resume"
                    ) from None
        bar.close()
