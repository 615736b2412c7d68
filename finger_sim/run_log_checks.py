"""Checks of a recorded run before a tool trusts it: states present, finite, in time order.

`resim` and `export` read a node's joint states and would otherwise report success on a log
whose states were removed ("0 states reproduced bit for bit"), hold a NaN (a NaN difference
never exceeds a running maximum) or are out of order (a scrambled CSV). `check_states`
refuses such a log with an `InvalidRunError`: one line naming the file, the first offending
message (its index and stamp) and what is wrong; the CLI exits with its own status for it.

A stamp equal to the one before is allowed only where the command log has a reset at that
stamp: the node publishes the reset state at the last state's stamp (its /clock never runs
backwards), so one stamp then carries the last state of one episode and the first of the next.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from os import PathLike

from finger_sim.run_log import NS_PER_S, RecordedRun, RunLogError


class InvalidRunError(RunLogError):
    """A log's recorded states cannot be trusted as a run (none, non-finite, out of order)."""


def check_states(run: RecordedRun, path: str | PathLike[str], topic: str = "/joint_states") -> None:
    """Raise InvalidRunError unless `run` has joint states, all finite, with non-decreasing stamps
    and no repeated stamp except at a reset (see the module)."""
    states = run.joint_states
    if not states:
        raise InvalidRunError(path, f"no joint states on {topic}: nothing to export or re-simulate")
    resets = {e.stamp_ns for e in run.events if e.event == "reset"}
    _check_finite(states, path, topic)
    _check_order([stamp for stamp, _ in states], resets, path, topic)


def _check_finite(states: Sequence[tuple[int, Sequence[float]]], path: str | PathLike[str], topic: str) -> None:
    for i, (stamp, state) in enumerate(states):
        if not all(math.isfinite(x) for x in state):
            bad = next(x for x in state if not math.isfinite(x))
            raise InvalidRunError(path, f"{topic} message {i} (stamp {stamp / NS_PER_S:.9f} s) holds a non-finite "
                                        f"value ({bad!r}): a log of a run must be finite")


def _check_order(stamps: Sequence[int], resets: Collection[int], path: str | PathLike[str], topic: str) -> None:
    for i in range(1, len(stamps)):
        before, now = stamps[i - 1], stamps[i]
        if now < before:
            raise InvalidRunError(path, f"{topic} message {i} is stamped {now / NS_PER_S:.9f} s, before the message "
                                        f"ahead of it ({before / NS_PER_S:.9f} s): messages out of time order")
        if now == before and now not in resets:
            raise InvalidRunError(path, f"{topic} message {i} repeats the stamp {now / NS_PER_S:.9f} s of the message "
                                        "ahead of it without a reset: a duplicated message")
