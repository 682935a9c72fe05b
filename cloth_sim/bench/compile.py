"""``cloth-sim bench compile``: where the kernels' compilation goes, kernel by kernel.

``make install`` compiles every numba kernel into numba's on-disk cache
(:func:`cloth_sim.kernels.compile_kernels`, its parts each in a process of its own); on a fresh
clone that is the longest stage of the install and of CI. This benchmark runs each part again in
a child process with an empty cache of its own (a temporary ``NUMBA_CACHE_DIR``), so every kernel
the part reaches is compiled, and prints the part's wall time and its kernels by exclusive compile
time: a kernel's own seconds, without those of the jitted functions it calls that numba compiles
on the way (a function inlined with ``inline="always"`` is compiled into its caller, so its cost
is the caller's). The times come from numba's event API (``numba:compile`` events,
``numba.core.event``).

With ``--side-by-side`` the parts run as ``make install`` runs them: all at once, sharing one empty
cache, so a kernel two parts reach is compiled by whichever asks first (the other finds it in the
cache, or compiles it too when both ask before either has written it: such a kernel is listed
under both parts).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager

from numba.core import event

from ..kernels import COMPILE_PARTS, compile_kernels

#: the prefix of the child's one line of results on its standard output
_MARK = "compile-profile: "


class CompileTimes(event.Listener):
    """Exclusive compile seconds per jitted function, from numba's ``numba:compile`` events: each
    event's span less the spans of the compilations nested in it (a callee numba compiles on the
    way). ``seconds[name]`` and ``counts[name]`` (signatures compiled) by the function's
    ``module.qualname``."""

    def __init__(self):
        self.seconds = defaultdict(float)
        self.counts = defaultdict(int)
        self._open = []  # (name, start, seconds of nested compilations)

    def on_start(self, ev):
        func = ev.data["dispatcher"].py_func
        self._open.append([f"{func.__module__}.{func.__qualname__}", time.perf_counter(), 0.0])

    def on_end(self, ev):
        name, start, nested = self._open.pop()
        span = time.perf_counter() - start
        self.seconds[name] += span - nested
        self.counts[name] += 1
        if self._open:
            self._open[-1][2] += span

    def rows(self) -> list[tuple[str, float, int]]:
        """``(name, seconds, signatures)``, the dearest first."""
        return sorted(
            ((n, s, self.counts[n]) for n, s in self.seconds.items()), key=lambda r: -r[1]
        )


@contextmanager
def listening():
    """A :class:`CompileTimes` that hears every compilation in the ``with`` block."""
    times = CompileTimes()
    with event.install_listener("numba:compile", times):
        yield times


def _child(part: str) -> None:
    """In the child: compile ``part`` (numba's cache is this process's empty one) and print the
    results as one JSON line."""
    with listening() as times:
        t0 = time.perf_counter()
        compile_kernels(part)
        wall = time.perf_counter() - t0
    print(_MARK + json.dumps({"part": part, "wall": wall, "rows": times.rows()}), flush=True)


def _start(part: str, cache: str) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    return subprocess.Popen(
        [sys.executable, "-m", "cloth_sim.bench.compile", "--child", part],
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )


def _result(proc: subprocess.Popen) -> dict:
    out, _ = proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"compiling a part failed (exit {proc.returncode})")
    for line in out.splitlines():
        if line.startswith(_MARK):
            return json.loads(line[len(_MARK) :])
    raise RuntimeError("the compiling process printed no results")


def profile_parts(parts, side_by_side: bool = False) -> tuple[list[dict], float]:
    """Each part compiled from an empty cache in a child process (one after the other, or all at
    once sharing one cache); returns each part's results and the wall time of them all."""
    results = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cloth_sim_compile_") as root:
        if side_by_side:
            procs = [_start(p, root) for p in parts]
            results = [_result(p) for p in procs]
        else:
            for i, part in enumerate(parts):
                results.append(_result(_start(part, os.path.join(root, str(i)))))
    return results, time.perf_counter() - t0


def print_compile_table(parts, top: int = 12, side_by_side: bool = False) -> None:
    """Print each part's wall time and its ``top`` dearest kernels (:func:`profile_parts`);
    ``parts``: :data:`cloth_sim.kernels.COMPILE_PARTS`' names, or none for all."""
    parts = list(parts or COMPILE_PARTS)
    unknown = [p for p in parts if p not in COMPILE_PARTS]
    if unknown:
        raise SystemExit(f"--parts: {unknown[0]!r} is not one of {', '.join(COMPILE_PARTS)}")
    results, wall = profile_parts(parts, side_by_side)
    how = "side by side, one shared cache" if side_by_side else "one after the other"
    print(f"kernels compiled from an empty cache, {how}: {wall:.1f} s wall in all")
    for r in results:
        total = sum(s for _, s, _ in r["rows"])
        print(f"\npart {r['part']}: {r['wall']:.1f} s ({total:.1f} s in numba's compiler)")
        print(f"{'seconds':>8}  {'sigs':>4}  kernel")
        for name, seconds, count in r["rows"][:top]:
            print(f"{seconds:8.1f}  {count:4d}  {name}")


if __name__ == "__main__" and sys.argv[1:2] == ["--child"]:
    _child(sys.argv[2])
