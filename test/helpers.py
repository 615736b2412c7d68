"""Helpers shared by the test layers, ROS-free: the console script as a user runs it."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

FINGER_SIM = Path(sys.executable).with_name("finger-sim")  # the venv's console script
NODE = "finger_sim.ros.node"  # the node's module, as `python -m` runs it
CLI_TIMEOUT_S = 120.0  # generous: two shared cores, other sessions running


def run_cli(*args: str | Path, timeout: float = CLI_TIMEOUT_S) -> subprocess.CompletedProcess:
    """`finger-sim ARGS...` in its own process; its exit status is the caller's to check."""
    return subprocess.run([str(FINGER_SIM), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          check=False)


def run_cli_here(*args: str | Path) -> subprocess.CompletedProcess:
    """`finger-sim ARGS...` called in this process (finger_sim.cli.main), its stdout, stderr and exit
    status as run_cli gives them: for the tests where the process boundary is not what is tested
    (each command keeps at least one test through run_cli). A traceback fails the test itself."""
    from finger_sim.cli import main

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main(argv)
        except SystemExit as exc:  # argparse's usage errors (status 2) and --help
            status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    return subprocess.CompletedProcess([str(FINGER_SIM), *argv], status, out.getvalue(), err.getvalue())


#: How long a killed recorder's writer process may take to write what it was handed, s.
WRITER_EXIT_S = 30.0


def child_pids(pid: int) -> list[int]:
    """The child processes of `pid` (e.g. a node's log writer), from /proc."""
    return [int(c) for p in Path(f"/proc/{pid}/task").glob("*/children") for c in p.read_text().split()]


def wait_until_gone(pids: list[int], timeout: float = WRITER_EXIT_S) -> None:
    """Wait until every process in `pids` (not our children) has exited: gone, or a zombie.

    A recorder's writer process outlives a killed caller until it has written what it was handed,
    so a log is read after it is done, not while it still grows."""
    deadline = time.monotonic() + timeout
    for pid in pids:
        stat = Path(f"/proc/{pid}/stat")
        while True:
            try:
                if stat.read_text().rsplit(")", 1)[1].split()[0] == "Z":
                    break
            except FileNotFoundError:
                break
            if time.monotonic() > deadline:
                raise AssertionError(f"process {pid} still runs after {timeout:g} s")
            time.sleep(0.01)


#: How long a blocked recorder may take to close once its FIFO has a reader, s (generous: shared cores).
BLOCKED_CLOSE_S = 20.0


@contextlib.contextmanager
def blocked_recorder(directory: Path, **options: Any) -> Iterator[tuple[Any, list[str]]]:
    """An open McapRecorder(**options) whose file is a FIFO nobody reads, and the list its
    `on_problem` appends to: its writer blocks opening the FIFO, so nothing leaves the queue.
    On leaving, even on a failure, the FIFO gets a reader and the recorder is closed."""
    from finger_sim.log import McapRecorder

    fifo = directory / "blocked.mcap"
    os.mkfifo(fifo)
    problems: list[str] = []
    recorder = McapRecorder(fifo, on_problem=problems.append, **options).open()
    try:
        yield recorder, problems
    finally:
        reader_fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # unblocks the writer
        try:
            recorder.close(timeout_s=BLOCKED_CLOSE_S)
        finally:
            os.close(reader_fd)


#: The shipped scenes whose Simulator steps through the compiled event step (DOP853 with the gap check;
#: not drive_grasp, whose drive steps its own mesh modes), the hand's finger among them.
EVENT_SCENES = ("grasp_cylinder", "press_table", "grasp_impact", "grasp_rigid", "paper_to_stop", "finger_default",
                "hard/chatter_wall", "hard/elastic_impact", "hard/grasp_release", "hard/rigid_fast",
                "hard/soft_pass_through", "hard/stops_elastic")
#: finger_default runs an hour (the node's default); its first seconds, s, hold its settling onto the stop.
SETTLE_S = 3.0


def event_scene(name: str) -> Any:
    """The shipped scene `name` (config/), finger_default cut to its first SETTLE_S."""
    from finger_sim.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parents[1] / "config" / f"{name}.yaml")
    return scene.with_overrides(duration=SETTLE_S) if name == "finger_default" else scene

#: Torque inputs (N·m, s) that exercise the event step: smooth ones evaluated at every stage, a step with
#: its switch inside a step, a square wave switching on the grid.
EVENT_PROFILES = {
    "ramp": {"type": "ramp", "offset": 0.005, "slope": 0.04},
    "sine": {"type": "sine", "amplitude": 0.02, "frequency": 3.0, "offset": 0.01},
    "step": {"type": "step", "before": 0.03, "after": -0.01, "at": 0.2005},  # a switch inside a step
    "square": {"type": "square", "amplitude": 0.02, "frequency": 4.0, "offset": 0.01},  # switches on the grid
}


def with_profile(name: str, profile: dict) -> Any:
    """`event_scene(name)` under the torque input `profile` (an input dict as scene files give it)."""
    from finger_sim.scene import scene_from_dict

    data = event_scene(name).to_dict()
    data["input"] = {"torque": profile}
    return scene_from_dict(data)
