"""A Simulator with a stateful actuator in the slot (`actuators.base.Actuator`): its integrator.

The actuator's own slots are stepped with q and q' in the flat state (`integrators.stateful`) by the
scene's explicit Runge-Kutta tableau, on the Python path. What it does not carry yet is refused in one
line: a scene with stops or contact (the rest mode and the impacts would hold q while the actuator's
state must go on: `actuators.inductive_stepping` does that for the drive alone), a drive scene (the
drive is the scene's actuator already), the compiled kernel, and a method without an explicit tableau.
"""

from __future__ import annotations

from finger_sim.actuators.base import Actuator
from finger_sim.errors import ConfigError
from finger_sim.integrators import METHODS, ExplicitRungeKutta, Integrator
from finger_sim.integrators.stateful import StatefulRungeKutta
from finger_sim.scene import AUTO, Scene
from finger_sim.simulation.setup import Setup

#: auto's method for an actuator with its own state when its own pick has no explicit tableau.
ACTUATED_DEFAULT = "rk6"


def integrator_class(scene: Scene, setup: Setup, actuator: Actuator, kernel: str) -> type[Integrator]:
    """The class stepping (q, q', the actuator's slots) for `scene`; ConfigError for what it cannot carry."""
    if kernel == "compiled":
        raise ConfigError("kernel", f"python or auto for the actuator {actuator.name!r} with its own state "
                          "(it has no compiled form)", kernel)
    if scene.drive is not None:
        raise ConfigError("model.drive", f"no drive with the actuator {actuator.name!r} (one actuator drives θ1)",
                          "a drive")
    if setup.gaps:
        raise ConfigError("model", f"a scene without stops or contact for the actuator {actuator.name!r} with its "
                          "own state (the rest and impact modes do not carry its slots yet)",
                          f"{len(setup.gaps)} gaps")
    method = setup.method_cls
    if not issubclass(method, ExplicitRungeKutta) and scene.method == AUTO:
        method = METHODS[ACTUATED_DEFAULT]
    return StatefulRungeKutta.of(method, 1, actuator)
