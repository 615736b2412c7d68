"""Outputs that never destroy data: written beside the target, renamed into place on success.

Every file a `finger-sim` command writes goes through `atomic_path`: the writer fills a
temporary file in the target's folder (same file system, so the rename is atomic), which is
flushed to disk and renamed over the target only when the writer returned. A failure (a full
disk, an interrupted run, an exception) leaves the old target as it was and removes the
temporary file, so no partial output (a CSV cut mid-row that reads as a shorter run) is left.

`check_distinct` refuses, before any work, an output that is one of the command's inputs or
another of its outputs, after resolving links (`export LOG --csv LOG` would replace the log).
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

from finger_sim.errors import ConfigError

#: Suffix of a temporary output before the target's own suffix (kept last: matplotlib picks
#: the image format from it).
PART_SUFFIX = ".part"
#: Mode of a new output before the umask, as `open(path, "w")` would create it.
NEW_FILE_MODE = 0o666


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_dir(folder: Path) -> None:
    """Make a rename in `folder` durable (best effort: some file systems refuse to open folders)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside `target` to write to; renamed onto `target` if the block succeeds.

    The temporary file keeps the target's suffix (`.keep.csv.x1y2.part.csv`); a target that is a
    link to a file is written through (the link's file is replaced, the link kept). The new file
    gets the mode of the file it replaces, or the umask's default for a new one.
    """
    target = Path(target)
    final = Path(os.path.realpath(target)) if target.is_symlink() else target
    try:
        fd, name = tempfile.mkstemp(dir=final.parent, prefix=f".{final.name}.", suffix=f"{PART_SUFFIX}{final.suffix}")
    except OSError as exc:  # name the file asked for, not the temporary one
        raise OSError(exc.errno, exc.strerror, str(target)) from None
    os.close(fd)
    temp = Path(name)
    try:
        yield temp
        try:
            mode = stat.S_IMODE(final.stat().st_mode)
        except FileNotFoundError:
            mode = NEW_FILE_MODE & ~_umask()
        os.chmod(temp, mode)
        with temp.open("rb+") as f:  # the writer may have closed its own handle: flush the data to disk
            os.fsync(f.fileno())
        os.replace(temp, final)
        _fsync_dir(final.parent)
    except BaseException:
        with contextlib.suppress(OSError):
            temp.unlink()
        raise


def _identity(path: Path) -> tuple[str, object]:
    """What makes two paths the same file: (device, inode) if it exists, else the resolved path."""
    try:
        st = os.stat(path)
    except OSError:
        return ("path", os.path.realpath(path))
    return ("inode", (st.st_dev, st.st_ino))


def check_distinct(inputs: Mapping[str, str | os.PathLike[str] | None],
                   outputs: Mapping[str, str | os.PathLike[str] | None]) -> None:
    """Refuse (ConfigError naming the option) an output that is an input or another output.

    inputs, outputs: argument name → path (None: not given). Paths are compared after
    resolving links and, for existing files, by device and inode (hard links too).
    """
    seen: dict[tuple[str, object], str] = {}
    for argument, path in inputs.items():
        if path is not None:
            seen.setdefault(_identity(Path(path)), argument)
    for argument, path in outputs.items():
        if path is None:
            continue
        key = _identity(Path(path))
        if key in seen:
            raise ConfigError(argument, f"a file other than {seen[key]} (it would be overwritten)", str(path))
        seen[key] = argument
