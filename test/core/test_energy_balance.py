"""The energy balance (cloth_sim.physics.energy_balance): a run that stays finite but holds energy
no source put in is marked unstable — in sweeps (status ``unstable``) and on /diagnostics (WARN) —
and a run driven by wind, pins or grippers is not."""

import math

import numpy as np

from cloth_sim.physics.energy_balance import EnergyBalance
from cloth_sim.scene import load_scene


def _run(sim, seconds):
    balance = EnergyBalance(sim)
    while sim.time < seconds:
        sim.step()
        balance.sample()
    return balance


def _hanging(n=16, factor=1.0):
    sim = load_scene("hanging_provot").build_simulator(rows=n, cols=n, spacing=1.0 / (n - 1))
    sim.dt = factor * sim.stable_dt()
    return sim


def test_a_step_far_above_its_limit_that_stays_finite_is_unstable():
    """Symplectic Euler 32× above stable_dt under the strain projection: bounded (finite, no
    divergence) and kinetic energy several times what the fall can give, which the balance sees."""
    sim = _hanging(factor=32.0)
    balance = _run(sim, 0.3)
    assert np.isfinite(sim.positions).all()
    fall = sim.model.masses.sum() * 9.81 * 1.0  # at most the cloth's side of fall, 1 m
    assert sim.energy()["kinetic"] > 2 * fall * 0.1
    assert balance.unstable and balance.excess > balance.allowed
    assert "energy balance" in balance.message() and "dt" in balance.message()


def test_stable_runs_are_balanced_whatever_drives_them():
    """Below stable_dt; the flag in its wind (the wind's work counted); a gripper lifting the cloth
    (its work counted): the excess stays far below what is allowed."""
    sim = _hanging(factor=0.9)
    balance = _run(sim, 0.5)
    assert not balance.unstable and balance.worst < 0.1
    sim = load_scene("flag").build_simulator()
    balance = _run(sim, 1.5)
    assert not balance.unstable and balance.worst < 0.1
    sim = load_scene("hanging_provot").build_simulator(rows=12, cols=12, spacing=1.0 / 11)
    sim.advance(0.5)
    corner = sim.positions[-1].copy()
    sim.grasp("g", corner, 0.01)
    balance = EnergyBalance(sim)
    for k in range(600):  # lift the far corner 0.6 m in 0.6 s
        sim.set_gripper_pose("g", corner + [0.0, 0.0, 0.001 * (k + 1)])
        sim.step()
        balance.sample()
    assert not balance.unstable and balance.worst < 0.2


def test_a_sweep_row_is_unstable_and_the_message_says_why(tmp_path):
    from cloth_sim.sweep import spec_from_dict
    from cloth_sim.sweep.run import execute

    spec = spec_from_dict(
        {
            "scene": "hanging_provot",
            "duration": 0.3,
            "frames": 0,
            "set": {"rows": 16, "cols": 16, "spacing": 1.0 / 15, "allow_unstable": True},
            "grid": {"dt": [0.0015, 0.0706]},
        }
    )
    rows = {run["dt"]: execute(spec, run, tmp_path) for run in spec.runs()}
    assert rows[0.0015]["status"] == "ok"
    assert rows[0.0706]["status"] == "unstable" and "energy balance" in rows[0.0706]["message"]
    assert math.isfinite(rows[0.0706]["kinetic"])
