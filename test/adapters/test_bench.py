"""`cloth-sim bench … --quick`: the outputs exist and are well formed, the quick sweep's observed
orders are the methods' orders, and the stability bisection finds symplectic Euler's linear limit.

Nothing here asserts a speed: the figures are the benchmarks' business (docs/BENCHMARKS.md).
"""

import csv
import json
import time

import numba
import numpy as np
import pytest

from cloth_sim.bench.compile import listening
from cloth_sim.bench.robot import INSIDE_SHARE
from cloth_sim.bench.robot import sweep as robot_sweep
from cloth_sim.cli import main as cli_main


def outputs(out, stem):
    assert (out / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / f"{stem}.csv") as f:
        rows = list(csv.DictReader(f))

    def no_nan(constant):
        raise AssertionError(f"{stem}.json holds {constant}, which is not JSON")

    data = json.loads((out / f"{stem}.json").read_text(), parse_constant=no_nan)
    md = (out / f"{stem}.md").read_text()
    assert rows and len(rows) == len(data["rows"]) and md.count("\n|") > len(rows)
    return rows, data, md


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("bench")


def test_work_precision_quick(bench_dir, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(bench_dir / "cache"))
    out = bench_dir / "wp"
    assert cli_main(["bench", "work-precision", "--quick", "--out", str(out)]) == 0
    rows, data, md = outputs(out, "work_precision")
    expected = {
        "explicit_euler": 1,
        "symplectic_euler": 1,
        "midpoint": 2,
        "rk4": 4,
        "verlet": 2,
        "implicit_euler": 1,
    }
    for name, order in expected.items():
        assert data["orders"][name] == pytest.approx(order, abs=0.2), name
    assert data["reference"]["agreement_m"] < 1e-9
    assert {r["integrator"] for r in rows} >= set(expected) | {
        "implicit_euler_prefactored",
        "kang",
    }
    for r in data["rows"]:
        assert (r["stable"] and r["rms_error"] <= r["max_error"] and r["wall_s"] > 0) or r[
            "failure"
        ]
        assert r["rms_error"] is not None or r["failure"]
    assert data["pareto"] and "Pareto" in md
    # the reference is cached on disk: a second run reads it instead of solving again
    assert list((bench_dir / "cache" / "cloth_sim" / "bench").glob("reference-*.npz"))


def test_the_convergence_figure_measures_each_method_against_the_fine_step_reference(bench_dir):
    """``cloth-sim bench convergence --work-precision``: every method's points and the reference's
    cost, written as a table and a figure; the reference is its own path, a converged ``vbd``
    step is nearer it than ten sweeps of one step a frame, and Baraff–Witkin comes nearer as its
    step shrinks (first order)."""
    out = bench_dir / "convergence"
    argv = ["bench", "convergence", "--work-precision", "--material", "cotton", "--sizes", "8"]
    assert cli_main([*argv, "--seconds", "0.5", "--out", str(out)]) == 0
    rows, data, md = outputs(out, "work_precision")
    by = {}
    for r in data["rows"]:
        by.setdefault(r["family"], []).append(r)
    ref = by.pop("symplectic Euler (the reference)")
    assert len(ref) == 1 and ref[0]["path"] == 0.0 and ref[0]["wall_s_per_s"] > 0
    assert sorted(len(v) for v in by.values()) == [3, 3, 3, 4, 4]
    converged = by["vbd, its defaults (over the tolerance)"]
    one_step = by["vbd, one step a frame (over its iterations)"]
    assert converged[1]["unconverged"] == 0
    assert converged[1]["path"] < one_step[0]["path"]
    bw = [r["path"] for r in by["Baraff–Witkin (over its step)"]]
    assert bw[0] > bw[1] > bw[2] > 0.0
    assert "Baraff–Witkin" in md


def test_the_rest_table_by_method_says_which_methods_rest_and_which_refuse_the_cloth(capsys):
    """``cloth-sim bench convergence --rest --methods``: a method that takes the cloth runs it
    from flat until at rest and holds the strain limit, so its free edge hangs within
    ``(1 + τ)`` of the sheet's length below the pins; one that cannot says why instead of
    failing the table (Kang takes no material's bending; explicit Euler has no stable step on
    an undamped cloth)."""
    argv = ["bench", "convergence", "--rest", "--strain-limit", "0.1", "--material", "cotton"]
    methods = "symplectic_euler,implicit_euler,kang,explicit_euler"
    assert cli_main([*argv, "--sizes", "8", "--seconds", "15", "--methods", methods]) == 0
    rows = {line.split()[2]: line for line in capsys.readouterr().out.splitlines()[2:]}
    assert set(rows) == set(methods.split(","))
    assert "bending" in rows["kang"] and "no stable step" in rows["explicit_euler"]
    for name in ("symplectic_euler", "implicit_euler"):
        dt, edge, worst, at_rest, speed = (float(v) for v in rows[name].split()[3:8])
        assert 0.0 < at_rest < 15.0 and speed < 1.0  # mm/s
        assert 0.9 < edge <= 1.1 * 1.0 and worst <= 0.1 + 2e-3


def test_stability_quick_brackets_the_linear_limit(bench_dir):
    out = bench_dir / "st"
    assert cli_main(["bench", "stability", "--quick", "--out", str(out)]) == 0
    rows, data, md = outputs(out, "stability")
    se = next(r for r in data["rows"] if r["integrator"] == "symplectic_euler")
    assert se["measured_dt"] == pytest.approx(se["linear_dt"], rel=0.15)
    assert se["measured_dt"] < se["unstable_dt"] <= se["measured_dt"] * 1.06
    assert data["stress"] and all(
        isinstance(s["survived"], bool) and s["what"] for s in data["stress"]
    )


def test_scaling_quick(bench_dir):
    out = bench_dir / "sc"
    assert cli_main(["bench", "scaling", "--quick", "--out", str(out)]) == 0
    rows, data, md = outputs(out, "scaling")
    assert all(float(r["ms_per_step"]) > 0 for r in rows)
    assert set(data["exponents"]) == {r["integrator"] for r in rows}
    names = [s["variant"] for s in data["skipping"]]
    assert names[0].startswith("everything on") and "none of them" in names
    assert "wind" in data["skipping"][0]["terms"] and "wind" not in data["skipping"][1]["terms"]


def test_the_garment_contacts_table_has_its_three_cases_and_counts_crossings(capsys):
    """``cloth-sim bench contacts --scene``: off, on and on as stiff as the cloth, each timed, the
    step without self-contact the ratios' base, and the crossings counted where self-contact is
    on (the T-shirt falling onto its table: none)."""
    from cloth_sim.bench.steps import print_garment_contacts_table

    rows = print_garment_contacts_table(("tshirt",), seconds=0.5, settle=0.25)
    assert [r["self_contact"] for r in rows] == ["off", "on", "on, 'cloth'"]
    assert rows[0]["ratio"] == 1.0 and all(r["ms"] > 0 for r in rows)
    assert rows[0]["crossings"] is None and rows[1]["crossings"] == rows[2]["crossings"] == 0
    out = capsys.readouterr().out
    assert out.count("\n| tshirt |") == 3 and "| heave, p99 (mm) | kinetic energy (J) |" in out
    # the shirt is still landing in this short run: every case's layers move
    assert all(r["heave_mm"] > 0.0 and r["kinetic"] > 0.0 for r in rows)


def test_the_robot_sweep_line_tallies_the_steps_with_a_vertex_inside_a_link(capsys):
    """``python -m cloth_sim.bench.robot``'s robot_sweep line: the deepest vertex inside a link,
    which link and when, and the steps that ended with a vertex deeper than a tenth of the
    thickness: a run with a deepest beyond that tenth has such a step, one within it none; every
    step is counted once."""
    seconds = 1.1  # (the arm reaches the cloth at ~0.8 s)
    row = robot_sweep(seconds)
    assert row["steps"] == round(seconds * 120) and 0 <= row["steps_inside"] <= row["steps"]
    assert (row["inside"] > INSIDE_SHARE) == (row["steps_inside"] > 0)
    assert row["link"].startswith("arm/") and 0.0 < row["at"] <= seconds + 1e-9
    out = capsys.readouterr().out
    tally = f"{row['steps_inside']} of {row['steps']} steps ending with a vertex over 10% of h"
    assert tally in out


def test_the_compile_profile_charges_each_kernel_its_own_seconds():
    """``cloth-sim bench compile``'s listener: a kernel numba compiles on the way into its caller
    is charged its own seconds, not the caller's too, so that every compilation's own seconds
    together lie within the call's span."""

    @numba.njit
    def callee(a):
        s = 0.0
        for v in a:
            s += v * v
        return s

    @numba.njit
    def caller(a):
        return callee(a) + 1.0

    with listening() as times:
        t0 = time.perf_counter()
        caller(np.ones(3))
        span = time.perf_counter() - t0
    rows = {name.rsplit(".", 1)[-1]: (s, n) for name, s, n in times.rows()}
    assert rows["caller"][1] == rows["callee"][1] == 1
    assert rows["caller"][0] > 0.0 and rows["callee"][0] > 0.0
    # each second charged once: the compilations nested in the caller's (the callee's, and any of
    # numba's own it needed) are not the caller's too, so their sum is within the call's span;
    # counted twice, the callee's would take it past the span
    total = sum(s for _, s, _ in times.rows())
    assert 0.5 * span < total <= span


def test_the_compile_profile_names_an_unknown_part(capsys):
    """A part that compile_kernels does not have is refused, naming the option and the parts."""
    with pytest.raises(SystemExit, match=r"--parts: 'steps2' is not one of grid_contacts"):
        cli_main(["bench", "compile", "--parts", "steps2"])


@pytest.mark.parametrize("text", ["10", "0x5", "5x-1", "tenx5", "10x5x2"])
def test_the_franka_peer_refuses_a_setting_that_is_not_steps_by_iterations(text, capsys):
    """``--ours`` takes STEPSxITERATIONS, two integers >= 1; anything else is refused before
    Newton or the shirt is touched, naming the option and the form."""
    with pytest.raises(SystemExit):
        cli_main(["bench", "franka-peer", "--ours", text])
    err = capsys.readouterr().err
    assert f"--ours {text!r}" in err and "STEPSxITERATIONS, two integers >= 1" in err
