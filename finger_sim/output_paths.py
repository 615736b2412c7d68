"""Checks of the files and folders a command will write, made before any work is done.

Every `finger-sim` command that writes (`simulate --csv/--plot`, `kinematics --plot`,
`export --csv/--plot`, `bench --out`) checks its paths here first, so a bad path is one
line naming the argument, never a traceback after a long run. The checks cannot foresee
everything (a full disk, a file system that refuses to create the file, as /proc does):
`finger-sim`'s main() reports an OSError of the write itself in one line too.

A plot path must end in an extension matplotlib writes: no extension is refused rather
than silently becoming `.png`, so what is printed as written is what was written.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from finger_sim.errors import ConfigError

#: Formats matplotlib writes only with an outside program: format → rcParams key naming it.
_NEEDS_PROGRAM = {"pgf": "pgf.texsystem"}


def plot_formats() -> list[str]:
    """File extensions (no dot, sorted) that matplotlib can write here."""
    import matplotlib
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    return sorted(f for f in formats if f not in _NEEDS_PROGRAM or shutil.which(matplotlib.rcParams[_NEEDS_PROGRAM[f]]))


def check_output_file(path: str | os.PathLike[str], *, argument: str) -> Path:
    """`path` as a Path if a file can be written there; ConfigError naming `argument` if not.

    Refused: an existing folder, a missing or non-folder parent, a parent or existing file
    this process may not write.
    """
    path = Path(path)
    parent = path.parent
    if "\0" in str(path):
        raise ConfigError(argument, "a file path without NUL characters", str(path))
    if path.is_dir():
        raise ConfigError(argument, "a file path, not a folder", str(path))
    if not parent.is_dir():
        problem = "no folder" if not parent.exists() else "not a folder:"
        raise ConfigError(argument, f"a file in an existing folder ({problem} {parent})", str(path))
    if path.exists() and not os.access(path, os.W_OK):
        raise ConfigError(argument, "a file this user may overwrite", str(path))
    if not path.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(argument, f"a file in a folder this user may write ({parent} is not)", str(path))
    return path


def check_plot_file(path: str | os.PathLike[str], *, argument: str) -> Path:
    """check_output_file, and the extension must be a format matplotlib writes (listed if not)."""
    path = check_output_file(path, argument=argument)
    formats = plot_formats()
    suffix = path.suffix.lower().removeprefix(".")
    if suffix not in formats:
        raise ConfigError(argument, f"an image file ending in one of {', '.join('.' + f for f in formats)}", str(path))
    return path


def check_output_dir(path: str | os.PathLike[str], *, argument: str) -> Path:
    """`path` as a Path if it is a writable folder or can be created; ConfigError naming `argument` if not."""
    path = Path(path)
    if "\0" in str(path):
        raise ConfigError(argument, "a folder path without NUL characters", str(path))
    existing = path.absolute()
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(argument, f"a folder ({existing} is a file)", str(path))
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(argument, f"a folder this user may write ({existing} is not)", str(path))
    return path
