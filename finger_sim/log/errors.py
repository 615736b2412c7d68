"""Errors of the logging layer: one hierarchy under LogError, messages built in the constructor.

Recorder misuse (bad arguments, wrong life-cycle order, a missing `.msg`) raises at the call.
I/O failures while recording never raise: the recorder reports them once and counts drops.
Reading a bad file raises one of the LogFileError subclasses, each naming the file and
what is wrong with it, so a command-line tool can print `str(err)` and exit nonzero.
"""

from __future__ import annotations

from collections.abc import Iterable
from os import PathLike
from pathlib import Path
from typing import Any



class LogError(Exception):
    """Base of every error raised by finger_sim.log (independent of the core's FingerSimError)."""


class LogArgumentError(LogError, ValueError):
    """An argument is invalid: names it, what is allowed and what arrived."""

    def __init__(self, argument: str, expected: str, got: Any) -> None:
        self.argument, self.expected, self.got = argument, expected, got
        super().__init__(f"{argument}: expected {expected}, got {got!r}")


class RecorderStateError(LogError, RuntimeError):
    """A recorder method was called in a life-cycle state that does not allow it."""

    def __init__(self, action: str, state: str) -> None:
        self.action, self.state = action, state
        super().__init__(f"cannot {action}: the recorder is {state}")


class MessageDefinitionNotFoundError(LogError, LookupError):
    """No `.msg` file for a type (or one of its field types) in any install prefix."""

    def __init__(self, type_name: str, searched: Iterable[Path]) -> None:
        self.type_name, self.searched = type_name, list(searched)
        where = ", ".join(str(p) for p in self.searched) or "no install prefix"
        super().__init__(
            f"no message definition for {type_name}: looked for {where} "
            "(source the ROS setup or install the message package)"
        )


class LogFileError(LogError):
    """A log file cannot be read as asked; `path` names it, `problem` says what is wrong."""

    def __init__(self, path: str | PathLike[str], problem: str) -> None:
        self.path, self.problem = Path(path), problem
        super().__init__(f"{self.path}: {problem}")


class LogNotFoundError(LogFileError):
    """The log file does not exist."""

    def __init__(self, path: str | PathLike[str]) -> None:
        super().__init__(path, "no such file")


class NotMcapError(LogFileError):
    """The file is not an MCAP file (empty, another format, random bytes, a directory)."""

    def __init__(self, path: str | PathLike[str], looks_like: str) -> None:
        self.looks_like = looks_like
        super().__init__(path, f"not an MCAP file ({looks_like})")


class TruncatedLogError(LogFileError):
    """The file ends inside a record: the recorder was killed or the disk filled up.

    The reader keeps the intact prefix readable and exposes this error as
    `LogReader.truncation` rather than raising it, so a tool can warn and exit nonzero.
    """

    def __init__(self, path: str | PathLike[str], offset: int, size: int, readable: int) -> None:
        self.offset, self.size, self.readable = offset, size, readable
        super().__init__(
            path,
            f"truncated at byte {offset} of {size}: no summary, the last record is cut off or missing "
            f"(the recorder was killed, or its disk was full); the {readable} messages before byte {offset} are readable",
        )


class CorruptLogError(LogFileError):
    """Bytes inside a complete log are malformed: a chunk fails to decompress or its CRC, a record
    does not parse, a message names an undeclared channel. `offset` is the record's byte, if known."""

    def __init__(self, path: str | PathLike[str], offset: int | None, reason: str) -> None:
        self.offset, self.reason = offset, reason
        where = f"corrupt record at byte {offset}" if offset is not None else "corrupt log"
        super().__init__(path, f"{where}: {reason}")


class MissingMetadataError(LogFileError):
    """An expected metadata record (e.g. 'finger_sim') is absent."""

    def __init__(self, path: str | PathLike[str], name: str, present: Iterable[str]) -> None:
        self.name, self.present = name, sorted(present)
        found = ", ".join(self.present) or "none"
        super().__init__(path, f"no metadata record {name!r} (records present: {found})")


class MissingTopicsError(LogFileError):
    """Expected topics are absent from the log."""

    def __init__(self, path: str | PathLike[str], missing: Iterable[str], present: Iterable[str]) -> None:
        self.missing, self.present = sorted(missing), sorted(present)
        found = ", ".join(self.present) or "none"
        super().__init__(path, f"missing topics {', '.join(self.missing)} (topics present: {found})")


class LogDecodeError(LogFileError):
    """Messages of a topic cannot be decoded as ROS 2 CDR with the schema stored in the file."""

    def __init__(self, path: str | PathLike[str], topic: str, reason: str) -> None:
        self.topic, self.reason = topic, reason
        super().__init__(path, f"cannot decode messages on {topic}: {reason}")
