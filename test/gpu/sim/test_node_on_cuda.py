"""The node on the CUDA backend (``-p device:=cuda``): it starts, steps and publishes its status,
and exits cleanly on SIGINT. On numba-cuda's simulator a 4×4 cloth steps at a few hundredths of
real time; what is checked is that the node's every use of the simulator works on the device's."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def test_the_node_runs_on_the_cuda_backend():
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(180 + os.getpid() % 40),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(ROOT / ".ros_log"),
        PYTHONUNBUFFERED="1",
    )
    args = ["device:=cuda", "rows:=4", "cols:=4", "strain_limit:=0.0", "publish_rate:=20.0"]
    argv = [str(Path(sys.executable).parent / "cloth_sim_node"), "--ros-args"]
    for a in args:
        argv += ["-p", a]
    proc = subprocess.Popen(
        argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    lines = []
    end = time.monotonic() + 300  # (the kernels compile at start-up where the cache is cold)
    try:
        while time.monotonic() < end:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if " rtf=" in line:  # the status the node logs every 5 s of wall time
                break
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        lines.append(out)
    text = "".join(lines)
    assert proc.returncode == 0 and "Traceback" not in text, text[-3000:]
    assert "symplectic_euler on the cuda" in text, text[-3000:]
    assert " rtf=" in text and "max_strain=" in text, text[-3000:]
