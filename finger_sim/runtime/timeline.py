"""Sim time of a node run across episodes: which stamp a step of the current episode gets.

The state after step n of an episode is stamped offset + round(n·dt·1e9) ns (run_records.stamp_ns,
the rule resim uses too). A reset restarts the scene's own clock, not /clock: the new episode's
offset is the last stamp + dt, so sim time on /clock never goes back.
"""

from __future__ import annotations

from finger_sim.run_records import stamp_ns


class Timeline:
    """Episode count and stamp offset of a run stepped at `dt` s."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.dt_ns = round(dt * 1e9)
        self.episode = 0
        self.offset_ns = 0

    def stamp(self, step: int) -> int:
        """Stamp of the state after `step` steps of the current episode, ns."""
        return stamp_ns(self.offset_ns, step, self.dt)

    def new_episode(self, last_stamp_ns: int) -> None:
        """A reset: the next episode's step 0 comes one dt after `last_stamp_ns`."""
        self.offset_ns = last_stamp_ns + self.dt_ns
        self.episode += 1
