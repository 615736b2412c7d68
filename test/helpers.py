"""Helpers shared by the test layers, ROS-free: the console script as a user runs it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

FINGER_SIM = Path(sys.executable).with_name("finger-sim")  # the venv's console script
NODE = "finger_sim.ros.node"  # the node's module, as `python -m` runs it
CLI_TIMEOUT_S = 120.0  # generous: two shared cores, other sessions running


def run_cli(*args: str | Path, timeout: float = CLI_TIMEOUT_S) -> subprocess.CompletedProcess:
    """`finger-sim ARGS...` in its own process; its exit status is the caller's to check."""
    return subprocess.run([str(FINGER_SIM), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          check=False)
