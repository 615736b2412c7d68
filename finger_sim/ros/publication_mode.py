"""Fast DDS's asynchronous publication mode for a stepping node under a real-time policy,
unless the user chose a mode.

rmw_fastrtps publishes synchronously by default: the publishing thread itself writes into each
subscriber's shared-memory port and takes that port's lock. Under SCHED_FIFO the node's stepping
thread then waits for whatever thread holds the lock: in the one-hour soak a 70 ms wait on a lock
held by the normal-priority controller (a priority inversion, docs/soak_realtime.md). In
ASYNCHRONOUS mode publish() hands the sample to Fast DDS's writer thread, which inherits the
node's real-time policy. At a normal policy the mode stays synchronous: there the writer thread
competes with everything else, and under load a keep-last history overwrites states it has not
sent yet (a subscriber misses them; test_recording's kill -9 test saw 3 of 1600 go).
Other rmw implementations ignore the variable.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

#: rmw_fastrtps's environment variable and the mode a real-time node prefers.
PUBLICATION_MODE_VAR = "RMW_FASTRTPS_PUBLICATION_MODE"
PREFERRED_MODE = "ASYNCHRONOUS"
#: The scheduling policies under which the node prefers it.
REALTIME_POLICIES = (os.SCHED_FIFO, os.SCHED_RR)


def prefer_async_publication(environ: MutableMapping[str, str] = os.environ, policy: int | None = None) -> str | None:
    """Under a real-time `policy` (default: this process's), set PUBLICATION_MODE_VAR to
    PREFERRED_MODE unless it is set (the user's choice wins); call before rclpy.init, which
    reads it. Returns the mode in effect (None: rmw's default)."""
    if (os.sched_getscheduler(0) if policy is None else policy) in REALTIME_POLICIES:
        environ.setdefault(PUBLICATION_MODE_VAR, PREFERRED_MODE)
    return environ.get(PUBLICATION_MODE_VAR)
