"""What a run's records say, without MCAP: the stamp rule and the command log's entries.

The stepping session (`finger_sim.runtime`) stamps and logs with these while it runs; `run_log`
reads them back from a log. Kept apart from `run_log`, which reads MCAP, so that the runtime
imports no MCAP until it records.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

from finger_sim.errors import FingerSimError, shown

NS_PER_S = 1_000_000_000


class RunLogError(FingerSimError):
    """A log lacks or garbles what a finger_node run needs: names the file and the problem."""

    def __init__(self, path: str | PathLike[str], problem: str) -> None:
        self.path, self.problem = Path(path), problem
        super().__init__(f"{self.path}: {problem}")


def stamp_ns(offset_ns: int, step: int, dt: float) -> int:
    """Sim time of the state after `step` steps of `dt` s in an episode starting at `offset_ns`, ns.

    The one timestamp rule: the node stamps its messages (headers, /clock) with it and resim
    compares by it. A message's MCAP log time is this stamp plus `log_time_offset_ns`.
    """
    return offset_ns + round(step * dt * 1e9)


@dataclass(frozen=True)
class CommandEvent:
    """One `~/command_log` entry: `torque` (N·m) is applied from `step` of `episode` on.

    The state at that step is stamped `stamp_ns`. Events 'accepted', 'timeout' and 'reset'
    change the applied torque; 'refused' only records a command that was not applied, and
    'lockstep_timeout' a state of a lockstep run that had no answer within lockstep_timeout: the
    torque held (`torque`) acts over step `step` without the controller's word.
    """

    event: str
    step: int
    episode: int
    stamp_ns: int
    torque: float
    requested: str = ""
    source: str = ""
    saturated: bool = False
    reason: str = ""

    APPLIES = ("accepted", "timeout", "reset")
    EVENTS = (*APPLIES, "refused", "lockstep_timeout")

    @property
    def applies_torque(self) -> bool:
        return self.event in self.APPLIES

    def to_values(self) -> dict[str, str]:
        """The DiagnosticStatus key-values; floats as repr() so that they round-trip exactly."""
        return {"event": self.event, "step": str(self.step), "episode": str(self.episode),
                "stamp_ns": str(self.stamp_ns), "torque": repr(self.torque), "requested": self.requested,
                "source": self.source, "saturated": str(self.saturated), "reason": self.reason}

    @classmethod
    def from_values(cls, values: Mapping[str, str], path: str | PathLike[str] = "log") -> CommandEvent:
        """Parse one entry's key-values; RunLogError names the key and the value."""
        def get(key: str, convert: Any, expected: str) -> Any:
            if key not in values:
                raise RunLogError(path, f"command log entry {shown(dict(values))}: lacks {shown(key)}")
            try:
                return convert(values[key])
            except (ValueError, OverflowError):
                raise RunLogError(path, f"command log key {key!r}: expected {expected}, "
                                        f"got {shown(values[key])}") from None

        event = get("event", str, "")
        if event not in cls.EVENTS:
            raise RunLogError(path, f"command log key 'event': expected one of {list(cls.EVENTS)}, got {shown(event)}")
        torque = get("torque", float, "a float") if event in cls.APPLIES or "torque" in values else 0.0
        if not math.isfinite(torque):
            raise RunLogError(path, f"command log key 'torque': expected a finite float, got {shown(values['torque'])}")
        return cls(event=event, step=get("step", int, "an int"), episode=get("episode", int, "an int"),
                   stamp_ns=get("stamp_ns", int, "an int (ns)"), torque=torque,
                   requested=values.get("requested", ""), source=values.get("source", ""),
                   saturated=values.get("saturated", "False") == "True", reason=values.get("reason", ""))
