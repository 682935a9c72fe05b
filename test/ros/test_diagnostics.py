"""/diagnostics carries the energy balance's warning (cloth_sim.ros.messages)."""

import pytest


def test_diagnostics_warn_with_the_balances_message():
    pytest.importorskip("rclpy")
    from diagnostic_msgs.msg import DiagnosticStatus

    from cloth_sim.ros import messages

    common = dict(
        error=None,
        paused=False,
        rtf=1.0,
        rtf_known=True,
        rtf_warn=0.95,
        dt=1e-3,
        stable_dt=1e-2,
        warn_margin=0.8,
        values={},
    )
    assert messages.diagnostic_status(**common).level == DiagnosticStatus.OK
    s = messages.diagnostic_status(**common, energy="energy balance: 40 J more …")
    assert s.level == DiagnosticStatus.WARN and "energy balance" in s.message
