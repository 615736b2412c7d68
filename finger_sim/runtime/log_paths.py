"""Where a node run's log goes: a file name built only from safe text, inside record_dir.

The name is `<scene>_<namespace>_<UTC start>.mcap`, each part reduced to a safe file-name
component (characters [A-Za-z0-9_.-], no leading dot, at most MAX_COMPONENT characters), so
no scene name ("../X", "/tmp/X") can put the file elsewhere; the resolved file is checked to
be directly inside the resolved record_dir all the same.

record_dir is resolved ('..' collapsed, symlinks followed) before any folder is made, and
only the missing folders of the resolved path are created: "a/../bags" creates bags only.
`LogFolder.remove_created()` takes them away again if the log cannot be written.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from finger_sim.errors import ConfigError

SUFFIX = ".mcap"
#: Longest component, characters: three of them plus a time stamp stay far below NAME_MAX (255).
MAX_COMPONENT = 64
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]")


def safe_component(text: str) -> str:
    """`text` as a file-name component: unsafe characters and leading dots become '_'."""
    safe = _UNSAFE.sub("_", text)[:MAX_COMPONENT]
    stripped = safe.lstrip(".")
    return "_" * (len(safe) - len(stripped)) + stripped


def utc_stamp(when: datetime) -> str:
    """ISO 8601 basic UTC time with milliseconds, e.g. 20240102T030405.678Z."""
    return when.strftime("%Y%m%dT%H%M%S.%f")[:-3] + "Z"


@dataclass
class LogFolder:
    """record_dir resolved, and the folders this run created for it (outermost first)."""

    path: Path
    created: list[Path] = field(default_factory=list)

    @classmethod
    def make(cls, record_dir: str) -> LogFolder:
        """Resolve `record_dir` and create its missing folders; OSError if one cannot be made
        (what was made is removed again)."""
        folder = cls(Path(record_dir).expanduser().resolve())
        missing = []
        for p in (folder.path, *folder.path.parents):
            if p.exists() or p.is_symlink():
                break
            missing.append(p)
        try:
            for p in reversed(missing):
                p.mkdir()
                folder.created.append(p)
        except OSError:
            folder.remove_created()
            raise
        return folder

    def remove_created(self) -> None:
        """Remove the folders this run created, innermost first, as long as they are empty."""
        for p in reversed(self.created):
            try:
                p.rmdir()
            except OSError:
                break
        self.created.clear()

    def new_file(self, *parts: str, started: datetime) -> Path:
        """Create (exclusively, so two runs never share one) `<parts>_<UTC start>[_i].mcap` here.

        Empty parts are left out. OSError if the folder does not take the file.
        """
        stem = "_".join(safe_component(p) for p in parts if p)
        stem = f"{stem}_{utc_stamp(started)}" if stem else utc_stamp(started)
        for i in range(1_000):  # two fingers started in the same millisecond
            path = self.path / (f"{stem}_{i}{SUFFIX}" if i else f"{stem}{SUFFIX}")
            if Path(os.path.abspath(path)).parent != self.path:
                raise ConfigError("log file name", f"a file directly inside {self.path}", str(path))
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            except FileExistsError:
                continue
            return path
        raise FileExistsError(f"{self.path}: no free log file name for {stem}")


def create_log_file(record_dir: str, *parts: str, started: datetime) -> Path:
    """A new, empty log file `<parts>_<UTC start>.mcap` in the resolved `record_dir`, made
    with its missing folders; OSError if that fails, and then no folder made here is left."""
    folder = LogFolder.make(record_dir)
    try:
        return folder.new_file(*parts, started=started)
    except OSError:
        folder.remove_created()
        raise


class UnwritableLog:
    """Stands in for the recorder when no log file can be made: writes nothing, counts every
    message as dropped, and says why in `error` (the recorder's interface, as far as the node uses it)."""

    def __init__(self, path: str, error: str) -> None:
        self.path = Path(path)
        self.error = error
        self.written = 0
        self.dropped = 0
        self.back_pressure = False  # nothing to wait for

    def write(self, topic: str, message: object, log_time_ns: int) -> bool:
        self.dropped += 1
        return False

    def write_records(self, topics: Sequence[str], datas: Sequence[bytes], log_time_ns: int) -> int:
        self.dropped += len(datas)
        return 0

    def cpu(self) -> None:
        """No threads, no process: recording costs nothing worth counting (the diagnostics show 0)."""
        return None

    def close(self) -> None:
        """Nothing to close."""
