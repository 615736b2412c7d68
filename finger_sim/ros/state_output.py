"""One hand-over to the log per published state, instead of one per message.

A step's state goes out as several messages (finger_node: /clock, joint_states, fingertip_pose;
a 10-finger finger_hand: 22). Logged one by one, each costs a McapRecorder.write (its checks,
its lock, its queue test). `StateOutput` collects the CDR messages published while
SteppingSession._publish_state runs, hands them to the log in one McapRecorder.write_records
(the same records, sequence numbers and times as write() gives them) and then sends them in the
order they were published. The state's topics, bytes and senders are kept in three lists reused
step after step: no object per message, and the recorder finds the same topic list every step.
Logged before sent: a controller's answer to a state, logged by the executor thread, never lands
in the log before that state.

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
        # the open state's messages, in the order published (cleared at flush, never reallocated)
        self._topics: list[str] = []
        self._datas: list[bytes] = []
        self._sends: list[Callable[[bytes], None]] = []

    def add(self, out: Endpoint, data: bytes, stamp: int) -> None:
        """Publish (and log, at `stamp` ns) a publisher's CDR bytes: now, or at `flush` inside a state."""
        recorder = self._recorder
        if recorder is None or not out.recorded:
            out.send(data)  # type: ignore[misc]  # a publisher's endpoint
        elif self._open:
            self._topics.append(out.topic)
            self._datas.append(data)
            self._sends.append(out.send)  # type: ignore[arg-type]
        else:
            out.send(data)  # type: ignore[misc]
            recorder.write(out.topic, data, stamp)

    def begin(self) -> None:
        """A state starts: collect its messages."""
        self._open = True

    def flush(self, stamp: int) -> None:
        """The state is complete: log what was collected at `stamp` ns in one hand-over, then send it."""
        self._open = False
        datas, sends = self._datas, self._sends
        if not datas:
            return
        try:
            self._recorder.write_records(self._topics, datas, stamp)
            for send, data in zip(sends, datas):
                send(data)
        finally:
            self._topics.clear()
            datas.clear()
            sends.clear()


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
