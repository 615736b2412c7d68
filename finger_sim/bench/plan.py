"""What `finger-sim bench` measures: the scenes, the methods and their grids, the peers, the rates.

The project's integrators over a grid of dt, scipy's solve_ivp over rtol on the same index-1
equations (and the same scalar right-hand side), MuJoCo's integrators over timestep on the
MJCF peer; the scene kinds and step rates of the recommendation table; the hard cases; the
contact scenes (spec §7), where `method: auto` itself is run too (its choice and its substeps
in contact are not one of the fixed methods); the drive scenes (spec §8). `tasks` turns this into the list of
measurements, in the order they run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import finger_sim
from finger_sim.bench.reference import Reference
from finger_sim.bench.runners import AUTO, Run, run_method, run_mujoco_peer, run_scipy
from finger_sim.errors import ConfigError
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene

#: Scenes with a work-precision figure (peers included), then the scenes measured for the
#: recommendation and hard cases only.
WP_SCENES = ("paper_flexion", "toggle_passage", "free_swing", "bang_bang", "stiff_spring")
#: Contact scenes (objects, spec §7) with a work-precision figure and the MuJoCo contact peer, then the contact
#: hard cases: the impact onto the cup and the near-rigid cup. Their scipy rows are solve_ivp restarted at every
#: located event (`runners.run_scipy`).
CONTACT_WP_SCENES = ("grasp_cylinder", "press_table")
CONTACT_HARD_SCENES = ("grasp_impact", "grasp_rigid")
CONTACT_SCENES = CONTACT_WP_SCENES + CONTACT_HARD_SCENES
#: The shipped drive scenes (spec §8: the motor, the gear train and its mesh modes, closing on the cup). Their
#: reference and scipy rows are solved piece by piece through the mesh's modes (`reference.solve_drive`).
DRIVE_SCENES = ("drive_grasp", "drive_grasp_backdrivable")
#: The hard contact scenes (config/hard/, not shipped scenes): the elastic fast impact, the chatter on a tilted
#: wall, grasp and release, the table with friction, the near-rigid fast impact, the elastic stops. `auto`
#: itself is run on them too (its error control is what they test).
ISSUE_HARD_FOLDER = "hard"
ISSUE_HARD_SCENES = ("elastic_impact", "chatter_wall", "grasp_release", "friction_table", "rigid_fast", "stops_elastic")
#: The shipped bench scenes (config/): each has scipy rows and `auto` itself run, for the goal table at auto's error.
SHIPPED_SCENES = WP_SCENES + ("paper_to_stop",) + CONTACT_SCENES + DRIVE_SCENES
ALL_SCENES = SHIPPED_SCENES + ISSUE_HARD_SCENES
#: Scene kinds of the recommendation table and the scenes measured for each (the same
#: kinds `finger_sim.auto.scene_kind` recognizes in a scene).
KINDS: dict[str, tuple[str, ...]] = {
    "smooth": ("paper_flexion", "free_swing", "toggle_passage"),
    "discontinuous": ("bang_bang",),
    "stiff": ("stiff_spring",),
    "stops": ("paper_to_stop",),
}
#: Step rates of the recommendation table, Hz.
RATES = (100, 1000, 10000)
#: Scenes judged as hard cases (at `analysis.HARD_DT`).
HARD_SCENES = ("toggle_passage", "free_swing", "bang_bang", "stiff_spring", "paper_to_stop") + CONTACT_HARD_SCENES
#: Errors are measured on this grid (s), or on a method's own coarser step grid.
SPACING = 1e-3
#: Timing repeats (median); runs longer than runners.LONG_RUN_SECONDS are timed once.
REPEATS = 3
#: `auto` is compared with scipy at the error it delivers at this dt (s): the shipped scenes' own step.
AUTO_DT = 1e-3
#: `integrator.tolerance` grid (rad) of `auto` at AUTO_DT on the shipped scenes (`runners.AUTO_TOLERANCE`): the
#: error-controlled dop853's work-precision front (rtol = 1e-3·tolerance), timed step by step and whole.
FULL_TOLERANCES = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
QUICK_TOLERANCES = (1e-4, 1e-6)
#: The project's methods that `simulate` runs offline in compiled stretches (`kernel.advance`: the compiled fast
#: path of a fixed-step method, dop853's whole output grid, a scene's event stretches, a stuck mesh's hold): on
#: the shipped scenes each of their runs is timed whole too. radau, rattle and adaptive step in Python, where a
#: whole run is the same loop of `Simulator.step`; their step-by-step CPU stands for their whole run.
WHOLE_RUN_METHODS = ("euler", "rk4", "rk6", "dop8", "dop853")

_COARSE = (1e-1, 5e-2, 2e-2)
_DECADES = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4)
_FINE = (5e-5, 2e-5, 1e-5)
#: dt grid per project method (full run). Each dt divides every scene's duration and is
#: a multiple or a divisor of SPACING. Cheap methods go down to 1e-5 s; the order-6 and
#: order-8 methods and the implicit ones stop at 1e-4 s, where they are at the reference
#: floor or their cost per run exceeds seconds; `adaptive` steps internally, its dt is only
#: the output rate.
FULL_DT: dict[str, tuple[float, ...]] = {
    "euler": _DECADES + _FINE,
    "rk4": _COARSE[1:] + _DECADES + _FINE,
    "rk6": _COARSE + _DECADES,
    "dop8": _COARSE + _DECADES,
    "rattle": _DECADES,
    "radau": _COARSE + _DECADES,
    "adaptive": (1e-2, 1e-3),
}
#: dt grid of a method FULL_DT does not list.
DEFAULT_DT = _DECADES
QUICK_DT = (1e-2, 1e-3)
FULL_RTOL = tuple(10.0**-k for k in range(3, 13))
QUICK_RTOL = (1e-4, 1e-8)
SCIPY_METHODS = ("RK45", "DOP853", "Radau", "LSODA")
#: The naive numpy right-hand side is shown on the paper's run only, with DOP853.
NUMPY_RHS_SCENE, NUMPY_RHS_METHOD = "paper_flexion", "DOP853"
FULL_TIMESTEPS = (1e-3, 1e-4, 1e-5)
QUICK_TIMESTEPS = (1e-3,)
MUJOCO_INTEGRATORS = ("Euler", "RK4", "implicitfast")
MUJOCO_SETTINGS = ("default", "tight")
#: The report's order of the project's methods (the paper's Euler first); others follow, sorted.
METHOD_ORDER = ("euler", "rk4", "rk6", "dop8", "rattle", "radau", "adaptive")


def config_dir() -> Path:
    """The scenes folder: `config/` beside the package (a source checkout), else under the cwd."""
    for candidate in (Path(finger_sim.__file__).resolve().parent.parent / "config", Path.cwd() / "config"):
        if (candidate / "paper_flexion.yaml").is_file():
            return candidate
    raise FileNotFoundError("finger-sim bench: no config/ folder with the scenes beside the package or in the cwd")


@dataclass(frozen=True)
class Task:
    """One measurement: a label for the progress bar and the call that makes the Run."""

    label: str
    call: Callable[[], Run]


def project_methods() -> list[str]:
    """Every integrator `METHODS` has, in the report's order (METHOD_ORDER, then the rest sorted)."""
    return [m for m in METHOD_ORDER if m in METHODS] + sorted(set(METHODS) - set(METHOD_ORDER))


def dt_grid(method: str, *, quick: bool) -> tuple[float, ...]:
    """The dt values (s) `method` is run at (AUTO: at the recommendation's rates)."""
    if method == AUTO:
        return QUICK_DT if quick else tuple(1.0 / rate for rate in RATES)
    return QUICK_DT if quick else FULL_DT.get(method, DEFAULT_DT)


def scene_methods(name: str) -> list[str]:
    """The project's methods run on a scene: every one, and AUTO itself."""
    return project_methods() + [AUTO]


def scene_file(name: str) -> Path:
    """The YAML file of a bench scene: config/<name>.yaml, config/hard/<name>.yaml for ISSUE_HARD_SCENES."""
    folder = config_dir()
    return (folder / ISSUE_HARD_FOLDER if name in ISSUE_HARD_SCENES else folder) / f"{name}.yaml"


def mujoco_tasks(name: str, scene: Scene, ref: Reference, *, quick: bool) -> list[Task]:
    """MuJoCo's integrators × settings × timesteps on one scene."""
    kw = {"spacing": SPACING, "repeats": REPEATS}
    return [
        Task(
            f"{name} MuJoCo {integrator} {setting} h={ts:g}",
            lambda s=scene, i=integrator, g=setting, h=ts, r=ref: run_mujoco_peer(s, i, h, g, r, **kw),
        )
        for integrator in MUJOCO_INTEGRATORS
        for setting in MUJOCO_SETTINGS
        for ts in (QUICK_TIMESTEPS if quick else FULL_TIMESTEPS)
    ]


def _accepts(scene: Scene, dt: float) -> bool:
    """Whether the scene takes step dt (s): one longer than half a square wave's period is refused."""
    try:
        scene.with_overrides(dt=dt)
    except ConfigError:
        return False
    return True


def whole_run_tasks(name: str, scene: Scene, ref: Reference, *, quick: bool, repeats: int = REPEATS) -> list[Task]:
    """A shipped scene's runs as a user running it offline gets them (`simulate`'s whole run), timed as scipy's
    `solve_ivp` is: auto at AUTO_DT, the WHOLE_RUN_METHODS over their dt grids, and auto over the tolerance grid
    at AUTO_DT step by step and whole."""
    kw = {"spacing": SPACING, "repeats": repeats}
    out = [Task(f"{name} {AUTO} whole run dt={AUTO_DT:g}",
                lambda s=scene, r=ref: run_method(s, AUTO, AUTO_DT, r, whole_run=True, **kw))]
    for method in WHOLE_RUN_METHODS:
        for dt in (d for d in dt_grid(method, quick=quick) if _accepts(scene, d)):
            out.append(Task(f"{name} {method} whole run dt={dt:g}",
                            lambda s=scene, m=method, d=dt, r=ref: run_method(s, m, d, r, whole_run=True, **kw)))
    for tol in QUICK_TOLERANCES if quick else FULL_TOLERANCES:
        for whole in (False, True):
            out.append(Task(f"{name} {AUTO} tolerance={tol:g}" + (" whole run" if whole else ""),
                            lambda s=scene, t=tol, w=whole, r=ref: run_method(s, AUTO, AUTO_DT, r, whole_run=w,
                                                                              tolerance=t, **kw)))
    return out


def tasks(scenes: dict[str, Scene], refs: dict[str, Reference], *, quick: bool, repeats: int = REPEATS,
          rtols: tuple[float, ...] | None = None) -> list[Task]:
    """The measurements, in the order they run: per scene the project's methods, then scipy and MuJoCo
    (each timed `repeats` times, the median kept); rtols: scipy's grid instead of QUICK_RTOL / FULL_RTOL."""
    out: list[Task] = []
    kw = {"spacing": SPACING, "repeats": repeats}
    for name, scene in scenes.items():
        ref = refs[name]
        for method in scene_methods(name):
            for dt in (d for d in dt_grid(method, quick=quick) if _accepts(scene, d)):
                out.append(Task(f"{name} {method} dt={dt:g}", lambda s=scene, m=method, d=dt, r=ref: run_method(s, m, d, r, **kw)))
        if name in CONTACT_WP_SCENES:
            out += mujoco_tasks(name, scene, ref, quick=quick)
        if name not in SHIPPED_SCENES:
            continue
        out += whole_run_tasks(name, scene, ref, quick=quick, repeats=repeats)
        for method in SCIPY_METHODS:
            for rtol in rtols or (QUICK_RTOL if quick else FULL_RTOL):
                out.append(Task(f"{name} scipy {method} rtol={rtol:g}", lambda s=scene, m=method, t=rtol, r=ref: run_scipy(s, m, t, r, **kw)))
        if name == NUMPY_RHS_SCENE:
            for rtol in QUICK_RTOL if quick else FULL_RTOL[1::2]:
                out.append(
                    Task(
                        f"{name} scipy {NUMPY_RHS_METHOD} numpy rtol={rtol:g}",
                        lambda s=scene, t=rtol, r=ref: run_scipy(s, NUMPY_RHS_METHOD, t, r, rhs="numpy", **kw),
                    )
                )
        if name in WP_SCENES:
            out += mujoco_tasks(name, scene, ref, quick=quick)
    return out
