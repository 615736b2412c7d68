"""The run's MCAP log, assembled: the file (runtime.log_paths), every recorded topic a channel, each
finger's resolved scene and run parameters in its metadata (run_log.run_metadata).

ROS-free: a channel names its message type ('pkg/msg/Type' or a message class) and, for a
publisher, its QoS profile (stored so that `ros2 bag play` offers the same). finger_sim.log (and
so MCAP) is imported only when a log is opened.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

from finger_sim.run_log import FINGER_SIM_METADATA, log_time_offset_ns, run_metadata
from finger_sim.runtime.log_paths import UnwritableLog, create_log_file
from finger_sim.runtime.parameters import RunSettings


@dataclass(frozen=True)
class Channel:
    """One recorded topic: its absolute name, message type and (a publisher's) QoS profile or None."""

    topic: str
    msg_type: str | type
    qos: Any = None


def open_run_log(settings: RunSettings, log_name: str, namespace: str, fingers: Sequence[Any], channels: Sequence[Channel],
                 *, on_problem: Callable[[str], None]) -> Any:
    """A started McapRecorder at <record_dir>/<log_name>[_<namespace>]_<UTC start>.mcap, its
    channels registered and one metadata record per finger (named finger_sim[/<finger name>]);
    or, if no file can be made, an UnwritableLog whose `error` says why (the run goes on without a
    log and counts what it lost). Back-pressure is on at realtime_factor 0; the recorder writes
    its status record (messages recorded and dropped) at close. `fingers`: finger_sim.ros.finger
    Fingers, or anything with their spec, scene and sim."""
    from finger_sim.log import RECORDING_STATUS, McapRecorder

    s = settings
    try:
        path = create_log_file(s.record_dir, log_name, namespace, started=datetime.now(timezone.utc))
    except OSError as exc:
        return UnwritableLog(s.record_dir, f"cannot create a log in record_dir '{s.record_dir}': {exc}")
    offset = log_time_offset_ns(s.record_time, time.time_ns())  # log time = stamp + offset
    rec = McapRecorder(path, chunk_interval_s=s.record_chunk_interval, on_problem=on_problem,
                       queue_size=s.record_queue_size, back_pressure=s.realtime_factor == 0.0,
                       status_record=RECORDING_STATUS, time_offset_ns=offset).open()
    for channel in channels:
        rec.register_channel(channel.topic, channel.msg_type, qos=channel.qos)
    for f in fingers:
        name = FINGER_SIM_METADATA + (f"/{f.spec.name}" if f.spec.name else "")
        rec.add_metadata(name, run_metadata(
            f.scene, method=f.sim.method, method_reason=f.sim.method_reason,
            torque_source=s.torque_source.value, parameters=s.to_values(), kernel=f.sim.kernel,
            record_time=s.record_time, log_time_offset_ns=offset))
    return rec
