"""MCAP logging: a non-blocking rosbag2-compatible recorder and a ROS-free reader.

Depends on mcap and mcap_ros2 only; rclpy is imported lazily, and only when the recorder is
handed message objects instead of CDR bytes. Nothing from the rest of finger_sim is imported
here: what a finger_node run stores is finger_sim.run_log's business.
"""

from mcap.writer import CompressionType

from .cdr import DiagnosticStatusFields, JointStateDecoder, JointStateFields, decode_diagnostic_status, decode_joint_state
from .definitions import DEFINITION_SEPARATOR, message_definition, type_name_of
from .errors import (
    CorruptLogError,
    LogArgumentError,
    LogDecodeError,
    LogError,
    LogFileError,
    LogNotFoundError,
    MessageDefinitionNotFoundError,
    MissingMetadataError,
    MissingTopicsError,
    NotMcapError,
    RecorderStateError,
    TruncatedLogError,
)
from .qos import OFFERED_QOS_PROFILES, offered_qos_profiles
from .reader import LogMessage, LogReader, TopicInfo, read_log
from .recorder import DEFAULT_CHUNK_INTERVAL_S, RECORDING_STATUS, McapRecorder, RecorderCpu

__all__ = [
    "DEFAULT_CHUNK_INTERVAL_S",
    "DEFINITION_SEPARATOR",
    "OFFERED_QOS_PROFILES",
    "RECORDING_STATUS",
    "DiagnosticStatusFields",
    "JointStateDecoder",
    "JointStateFields",
    "CompressionType",
    "CorruptLogError",
    "LogArgumentError",
    "LogDecodeError",
    "LogError",
    "LogFileError",
    "LogMessage",
    "LogNotFoundError",
    "LogReader",
    "McapRecorder",
    "RecorderCpu",
    "MessageDefinitionNotFoundError",
    "MissingMetadataError",
    "MissingTopicsError",
    "NotMcapError",
    "RecorderStateError",
    "TopicInfo",
    "TruncatedLogError",
    "decode_diagnostic_status",
    "decode_joint_state",
    "message_definition",
    "offered_qos_profiles",
    "read_log",
    "type_name_of",
]
