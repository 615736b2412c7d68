"""One hand-over to the log per published state, instead of one per message.

A step's state goes out as several messages (finger_node: /clock, joint_states, fingertip_pose;
a 10-finger finger_hand: 22). Logged one by one, each costs a McapRecorder.write (its checks,
its lock, its queue test). `StateOutput` collects the CDR messages published while
SteppingSession._publish_state runs, hands them to the log in one McapRecorder.write_batch
(the same records, sequence numbers and times as write() gives them) and then sends them in the
order they were published. Logged before sent: a controller's answer to a state, logged by the
executor thread, never lands in the log before that state.

Outside a state (an idle /clock repeat, diagnostics, command-log events) and without a log, a
message is sent (and logged) at once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from finger_sim.ros.interfaces import Endpoint


class StateOutput:
    """The stepping thread's way out for CDR messages; `recorder`: the run's log or None."""

    def __init__(self, recorder: Any) -> None:
        self._recorder = recorder
        self._open = False
        self._sends: list[tuple[Callable[[bytes], None], bytes]] = []
        self._logged: list[tuple[str, bytes]] = []

    def add(self, out: Endpoint, data: bytes, stamp: int) -> None:
        """Publish (and log, at `stamp` ns) a publisher's CDR bytes: now, or at `flush` inside a state."""
        recorder = self._recorder
        if recorder is None or not out.recorded:
            out.send(data)  # type: ignore[misc]  # a publisher's endpoint
        elif self._open:
            self._sends.append((out.send, data))  # type: ignore[arg-type]
            self._logged.append((out.topic, data))
        else:
            out.send(data)  # type: ignore[misc]
            recorder.write(out.topic, data, stamp)

    def begin(self) -> None:
        """A state starts: collect its messages."""
        self._open = True

    def flush(self, stamp: int) -> None:
        """The state is complete: log what was collected at `stamp` ns in one hand-over, then send it."""
        self._open = False
        if not self._sends:
            return
        sends, logged = self._sends, self._logged
        self._sends, self._logged = [], []
        self._recorder.write_batch(logged, stamp)
        for send, data in sends:
            send(data)


class BatchedStateOutput:
    """Mixin for a SteppingSession adapter with a StateOutput in `_output`: every published state
    (`_publish_state`) leaves through one hand-over."""

    _output: StateOutput
    stamp_ns: int

    def _publish_state(self, *, force: bool = False) -> None:
        self._output.begin()
        try:
            super()._publish_state(force=force)  # type: ignore[misc]
        finally:
            self._output.flush(self.stamp_ns)
