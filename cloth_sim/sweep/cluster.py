"""Joining a running Ray cluster (``cloth-sim sweep --address``) that may ask for a token.

Ray 2.60 turns token authentication on for a cluster that ``ray start --head`` makes where a token
exists (``~/.ray/auth_token``: a local ``ray.init()``, such as a sweep without ``--address``,
writes one), and a driver that joins by address must then say ``RAY_AUTH_MODE=token`` and have the
token (https://docs.ray.io/en/latest/ray-security/token-auth.html). Ray itself turns it on only for
a cluster it finds by itself (``address="auto"``), never for an explicit address. So the sweep does
what Ray's documentation asks of a user: when joining by address with ``RAY_AUTH_MODE`` unset and a
token at hand (``RAY_AUTH_TOKEN``, the file ``RAY_AUTH_TOKEN_PATH`` names, or
``~/.ray/auth_token``, in Ray's order), it joins with token authentication. A cluster without
authentication accepts such a driver too. ``RAY_AUTH_MODE`` set by the user is left alone.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from pathlib import Path

MODE = "RAY_AUTH_MODE"


def token_source() -> str | None:
    """Where Ray would read a token from (a description), or ``None`` when there is none."""
    if os.environ.get("RAY_AUTH_TOKEN", "").strip():
        return "RAY_AUTH_TOKEN"
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    if path and Path(path).expanduser().is_file():
        return f"RAY_AUTH_TOKEN_PATH ({path})"
    default = Path.home() / ".ray" / "auth_token"
    if default.is_file():
        return str(default)
    return None


def prepare_join(address: str | None) -> str | None:
    """Before ``ray.init(address=address)``: token authentication on when joining by address with
    ``RAY_AUTH_MODE`` unset and a token at hand; returns the token's source when it did so."""
    if not address or os.environ.get(MODE):
        return None
    source = token_source()
    if source is None:
        return None
    os.environ[MODE] = "token"
    if (
        "ray" in sys.modules
    ):  # Ray read its configuration when it was imported: again, with the mode
        raylet = getattr(sys.modules["ray"], "_raylet", None)
        config = getattr(raylet, "Config", None)
        if config is not None:
            config.initialize("")
    return source


def join_error(address: str, error: BaseException) -> str | None:
    """One paragraph saying what to set, when ``error`` (from ``ray.init``) is the cluster refusing
    the driver's authentication; ``None`` for any other failure."""
    text = f"{error} {error.__cause__ or ''}"
    if "InvalidAuthToken" not in text and "Authentication" not in text:
        return None
    mode = os.environ.get(MODE) or "unset"
    then = (
        "and unset RAY_AUTH_MODE (or set it to token)"
        if mode.lower() not in ("token", "unset")
        else "(RAY_AUTH_MODE=token is then set for you)"
    )
    return (
        f"--address {address}: the Ray cluster refused this driver's authentication "
        f"(RAY_AUTH_MODE {mode}, token from {token_source() or 'nowhere'}). A cluster started "
        f"with token authentication needs its token here: copy the head node's "
        f"~/.ray/auth_token (`ray get-auth-token` on the head prints it) to ~/.ray/auth_token, "
        f"or set RAY_AUTH_TOKEN to it, or RAY_AUTH_TOKEN_PATH to a file holding it, {then}"
    )


#: each Ray worker's threads: one task a CPU, one thread a task
WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


@contextlib.contextmanager
def session(workers: int | None, address: str | None, error=ValueError):
    """Ray for a driver: this process's connection if it has one, else a cluster joined at
    ``address`` (with token authentication as above; a refusal raised as ``error`` saying what to
    set), else Ray started here with ``workers`` CPUs (default all). Yields the number of tasks to
    keep running (``workers``, or the cluster's CPUs); shuts down what it started."""
    running = "ray" in sys.modules and sys.modules["ray"].is_initialized()
    source = prepare_join(address) if not running else None
    import ray

    started = not ray.is_initialized()
    if started:
        kw = dict(
            include_dashboard=False,
            logging_level=logging.WARNING,
            runtime_env={"env_vars": WORKER_ENV},
        )
        if address:
            if source:
                print(
                    f"joining {address} with token authentication (the token from {source})",
                    file=sys.stderr,
                )
            try:
                ray.init(address=address, **kw)
            except Exception as e:  # Ray raises ConnectionError, the AuthenticationError its cause
                message = join_error(address, e)
                if message is None:
                    raise
                raise error(message) from None
        else:
            ray.init(address="local", num_cpus=workers or os.cpu_count(), **kw)
    try:
        yield workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
    finally:
        if started:
            ray.shutdown()


@contextlib.contextmanager
def pool_map(workers: int, address: str | None, error=ValueError):
    """A ``map`` whose calls run on Ray's workers (:func:`session`; a ``ray.util.multiprocessing``
    pool of ``workers`` processes, or of the cluster's CPUs at ``address``): what a fit's
    optimiser spreads its candidates with."""
    with session(workers, address, error) as n:
        from ray.util.multiprocessing import Pool

        pool = Pool(processes=n)
        try:
            yield pool.map
        finally:
            pool.terminate()
