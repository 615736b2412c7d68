"""node_bench --old: each side's node imports its own checkout's finger_sim, even when the bench is started from
inside the other checkout (`python -m` puts the working folder first on sys.path unless PYTHONSAFEPATH is set)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from finger_sim.bench.node_bench import side_envs
from finger_sim.bench.processes import ROOT


def _checkout(folder: Path, mark: str) -> Path:
    """A stand-in checkout whose finger_sim package says which it is."""
    (folder / "finger_sim").mkdir(parents=True)
    (folder / "finger_sim" / "__init__.py").write_text(f"MARK = {mark!r}\n")
    (folder / "finger_sim" / "which.py").write_text("import finger_sim\nprint(finger_sim.MARK, finger_sim.__file__)\n")
    return folder


def test_each_side_runs_its_own_checkout_from_inside_another(tmp_path: Path) -> None:
    old = _checkout(tmp_path / "old", "old")
    here = _checkout(tmp_path / "here", "here")  # the working folder: a checkout neither side is
    envs = side_envs(old, 0)
    run = subprocess.run([sys.executable, "-m", "finger_sim.which"], env=envs["old"], cwd=here, capture_output=True,
                         text=True, check=True)
    assert run.stdout.split()[0] == "old"
    assert envs["new"]["PYTHONPATH"].split(":")[0] == str(ROOT)
    assert envs["old"]["PYTHONSAFEPATH"] == envs["new"]["PYTHONSAFEPATH"] == "1"
