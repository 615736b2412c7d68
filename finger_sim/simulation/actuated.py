"""A Simulator with a stateful actuator in the slot (`actuators.base.Actuator`): its integrator.

The actuator's own slots are stepped with q and q' in the flat state (`integrators.stateful`) by the
scene's explicit Runge-Kutta tableau; an actuator that declares its law (`actuators.base.ActuatorLaw`)
runs on the compiled kernel where the scene's elements do (`kernel.stateful`, picked by auto), any other
on the Python path. With stops or contact the Simulator's events carry its slots
(`simulation.actuated_events`). An actuator that declares a `time_constant` (s) has its
own mode s = −1/T checked like the linkage's: auto splits each step to resolve it, a named method that
is unstable on it is refused. What it does not carry is refused in one line: stick–slip friction on a
moving object, a constrained actuator (its own `accelerations`) with gaps, a drive scene (the drive is the
scene's actuator already), the compiled kernel for an actuator without a declared law, and a method
without an explicit tableau. auto's kernel falls back to the Python path and says why in the method's reason.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from finger_sim import stepper_slot, stick_slip
from finger_sim.actuators.base import Actuator
from finger_sim.auto import contact_substeps
from finger_sim.errors import ConfigError
from finger_sim.integrators import METHODS, ExplicitRungeKutta, Integrator
from finger_sim.integrators.stateful import StatefulRungeKutta
from finger_sim.scene import AUTO, Scene
from finger_sim.simulation.setup import Setup, check_stability

#: auto's method for an actuator with its own state when its own pick has no explicit tableau.
ACTUATED_DEFAULT = "rk6"
#: auto's substep resolves the actuator's own mode: h/T ≤ this (as the inductive drive's
#: `actuators.inductive.ELECTRICAL_RESOLUTION`; rk4's bound on the real axis is 2.79).
OWN_RESOLUTION = 0.25
#: Most substeps auto takes per step for the actuator's mode; beyond that T is far below dt.
MAX_OWN_SUBSTEPS = 1024


class Actuated(NamedTuple):
    """What a Simulator with a stateful actuator runs: its integrator class, the contact substeps
    (`Simulator.substeps`), its kernel and what the method's reason adds."""

    integrator_cls: type[Integrator]
    substeps: int
    #: the kernel it runs on: "numba-<version>" or "python"
    kernel: str
    note: str


def integrator_class(scene: Scene, setup: Setup, actuator: Actuator, kernel: str) -> Actuated:
    """The class stepping (q, q', the actuator's slots) for `scene` on `kernel` (compiled where the actuator
    declares its law, `actuators.base.ActuatorLaw`), its contact substeps and the reason's note; ConfigError
    for what it cannot carry."""
    if kernel not in ("python", "auto") and getattr(actuator, "law", None) is None:
        raise ConfigError("kernel", f"python or auto for the actuator {actuator.name!r} with its own state "
                          "(it has no compiled form)", kernel)
    if scene.drive is not None:
        raise ConfigError("model.drive", f"no drive with the actuator {actuator.name!r} (one actuator drives θ1)",
                          "a drive")
    friction = stick_slip.element(setup.system)
    if friction is not None and friction.time_varying:
        raise ConfigError("objects", f"fixed objects with stick–slip friction for the actuator {actuator.name!r} with "
                          "its own state (riding a moving object does not carry its slots)", "a moving object")
    if setup.gaps and type(actuator).accelerations is not Actuator.accelerations:
        raise ConfigError("model", f"a scene without stops or contact for the actuator {actuator.name!r}, which "
                          "writes its own accelerations (a constrained actuator)", f"{len(setup.gaps)} gaps")
    method, substeps = setup.method_cls, setup.substeps
    note = ""
    if not issubclass(method, ExplicitRungeKutta) and scene.method == AUTO:
        method, substeps = METHODS[ACTUATED_DEFAULT], contact_substeps(scene)
        check_stability(scene, setup.system, method, substeps)
        note += f"; {method.name} instead (the slots of the actuator {actuator.name!r} need an explicit tableau)"
    n = own_substeps(scene, method, actuator)
    if n > 1:
        note += f"; {n} substeps per step resolve the time constant {actuator.time_constant:g} s of the actuator {actuator.name!r}"
    integrator_cls, name, why_python = stepper_slot.kernel().select_stateful(
        StatefulRungeKutta.of(method, n, actuator), setup.system, kernel)
    if why_python:
        note = f"; {why_python}: the Python path{note}"
    return Actuated(integrator_cls, substeps, name, note)


def own_substeps(scene: Scene, method: type[Integrator], actuator: Actuator) -> int:
    """Substeps per step for the actuator's own mode s = −1/T (T: its `time_constant`, s; none: 1): auto's
    ceil(dt/(T·OWN_RESOLUTION)); a named method takes 1 and is refused (ConfigError) where it is unstable
    on the mode at dt."""
    from finger_sim.stability import largest_stable_dt, stable_at

    tau = actuator.time_constant
    if tau is None:
        return 1
    root = complex(-1.0 / tau)
    if scene.method == AUTO:
        n = max(1, math.ceil(scene.dt / (tau * OWN_RESOLUTION)))
        if n > MAX_OWN_SUBSTEPS:
            raise ConfigError("integrator.dt", f"a step that resolves the time constant {tau:g} s of the actuator "
                              f"{actuator.name!r} in at most {MAX_OWN_SUBSTEPS} substeps", scene.dt)
        return n
    ref = getattr(method, "reference", method)
    if not stable_at(ref, root, scene.dt):
        raise ConfigError("integrator.method", f"auto, or dt ≤ {largest_stable_dt(ref, root, scene.dt):.3g} s",
                          method.name, problem=f"{method.name} is unstable on the time constant {tau:g} s of the "
                          f"actuator {actuator.name!r} at dt = {scene.dt:g} s")
    return 1
