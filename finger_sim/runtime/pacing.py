"""Real-time pacing of a fixed-step loop on the wall clock, and its late wake-ups.

Step n of a pacing run is due at anchor + n·dt/realtime_factor wall seconds, the anchor being
the first tick after a start, resume or reset (step 1 is due then). The loop asks `due(now)`
and runs that many steps, or sleeps until `next_due`: a late wake-up is caught up, so the mean
rate stays exact. A wake-up that finds more than one step due is an overrun; a backlog beyond
`catchup_limit_s` of wall time is dropped (the anchor moves on, sim time slips behind wall
time, the dropped steps are counted) rather than run in a burst; a backlog within it is run
in one burst (counted as an overrun, its lateness in `lateness`), so sim time keeps tracking
wall time.

Physics time never comes from here: the caller advances its simulator by whole steps of dt.
"""

from __future__ import annotations

import numpy as np

from finger_sim.errors import ConfigError

#: Wall-time backlog that pacing catches up; beyond it the backlog is dropped and counted. The
#: one-hour soak's late windows were single stalls of 70-100 ms (a lock wait, hypervisor steal):
#: 0.25 s catches such a stall up in a burst (at 1 kHz, 250 steps of ~0.1 ms CPU each, ~25 ms)
#: instead of dropping it, while a longer stall (a suspended process) still slips rather than
#: replaying seconds of steps at once. Node parameter `catchup_limit`.
CATCHUP_LIMIT_S = 0.25
#: Slack of the float comparison on the wall-time grid, in steps.
GRID_EPS = 1e-9


class Lateness:
    """Late wake-ups (wall s), binned so that a percentile costs microseconds (it is taken
    inside the stepping loop, once per diagnostics period)."""

    BIN_S = 1e-5
    BINS = 20_000  # up to 200 ms; later ones land in the last bin (the max is kept exactly)

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def add(self, late: float) -> None:
        self.counts[min(int(max(late, 0.0) / self.BIN_S), self.BINS - 1)] += 1
        self.n += 1
        if late > self.max:
            self.max = late

    def percentile(self, p: float) -> float:
        """Upper edge of the bin holding the p-th percentile, s (0 with no samples)."""
        if not self.n:
            return 0.0
        i = int(np.searchsorted(np.cumsum(self.counts), p / 100.0 * self.n))
        return min((i + 1) * self.BIN_S, self.max) if i < self.BINS - 1 else self.max


class Pacer:
    """Which steps are due at a given wall time (s, any monotonic clock).

    dt: sim s per step; realtime_factor: sim s per wall s (> 0); catchup_limit_s: wall s of
    backlog caught up before the rest is dropped. Counters since construction: overruns,
    dropped_steps, lateness; `window` holds the late wake-ups since the last `new_window()`.
    """

    def __init__(self, dt: float, realtime_factor: float, catchup_limit_s: float = CATCHUP_LIMIT_S) -> None:
        self.dt, self.catchup_limit_s = dt, catchup_limit_s
        self.set_realtime_factor(realtime_factor)
        self.overruns = 0
        self.dropped_steps = 0
        self.lateness = Lateness()
        self.window = Lateness()
        self._anchor: float | None = None  # wall time of step 0 of the current pacing run
        self._steps = 0  # steps handed out since the anchor

    def set_realtime_factor(self, realtime_factor: float) -> None:
        """A new pace (sim s per wall s, > 0), from a new pacing run on; the counters go on."""
        if not realtime_factor > 0:
            raise ConfigError("realtime_factor", "> 0 for a paced loop", realtime_factor)
        self.wall_per_step = self.dt / realtime_factor
        self.catchup_steps = max(1, int(self.catchup_limit_s / self.wall_per_step))
        self.restart()

    def restart(self) -> None:
        """The next `due()` starts a new pacing run (after a start, resume or reset)."""
        self._anchor = None

    def new_window(self) -> None:
        self.window = Lateness()

    @property
    def next_due(self) -> float:
        """Wall time at which the next step is due (after a first `due()` of the run)."""
        assert self._anchor is not None, "next_due before due()"
        return self._anchor + (self._steps + 1) * self.wall_per_step

    def due(self, now: float) -> int:
        """Steps to run now (0: sleep until `next_due`); the caller runs them all, or restarts."""
        wps = self.wall_per_step
        if self._anchor is None:  # first tick of a run: step 1 is due now
            self._anchor, self._steps = now - wps, 0
        next_due = self._anchor + (self._steps + 1) * wps
        if now < next_due:
            return 0
        due = int((now - self._anchor) / wps + GRID_EPS) - self._steps
        late = now - next_due
        self.lateness.add(late)
        self.window.add(late)
        if due > 1:
            self.overruns += 1
        if due > self.catchup_steps:  # too far behind: drop the backlog, slip behind the wall clock
            dropped = due - self.catchup_steps
            self.dropped_steps += dropped
            self._anchor += dropped * wps
            due = self.catchup_steps
        self._steps += due
        return due
