"""The contact effect's scene keys as pydantic models (spec §7): `model.contact` (the law and its friction
law), `model.phalanx_radius` and the top-level `objects` with their own law, strength and motion.

Bounds and defaults are the loader's own (`contact_geometry`, `friction_modes` and the scene's
MAX_CONTACT_* constants), so an editor refuses what `finger_sim.scene.load_scene` refuses. Checks between
keys that JSON Schema cannot state stay the loader's: μ_s ≥ μ_k, object names that differ, a non-zero
normal or direction, stick_slip with a moving object and a drive or joint limits.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from finger_sim.effects.contact_geometry import (MAX_MOTION_EXTENT, MAX_MOTION_FREQUENCY, MAX_MOTION_TIME,
                                                 PHALANX_RADII, ContactParams)
from finger_sim.effects.friction_modes import (FRICTION_MODELS, MAX_STATIC_FRICTION, MAX_STRIBECK_VELOCITY,
                                               MIN_STRIBECK_VELOCITY, REGULARIZED, STICK_SLIP)
from finger_sim.effects.parameters import bounded, pair_of
from finger_sim.scene import (MAX_CONTACT_DAMPING, MAX_CONTACT_EXPONENT, MAX_CONTACT_STIFFNESS, MAX_EXTENT, MAX_FRICTION,
                              MIN_SLIP_VELOCITY, NAME_LENGTH)

_LAW = ContactParams()
#: `static_friction` and `stribeck_velocity` belong to stick_slip: absent unless `friction_model: stick_slip`.
_STICK_SLIP_ONLY = {
    "if": {"not": {"required": ["friction_model"], "properties": {"friction_model": {"const": STICK_SLIP}}}},
    "then": {"properties": {"static_friction": False, "stribeck_velocity": False}},
}


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ContactLaw(_Closed):
    """`model.contact`: F_n = max(0, k δ^e (1 + d δ')), F_t = −μ F_n tanh(v_t / v_s), or exact stick–slip."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_STICK_SLIP_ONLY)
    stiffness: bounded("contact stiffness k_c (N/m^e)", minimum=0.0, maximum=MAX_CONTACT_STIFFNESS, strict=True,
                       default=_LAW.stiffness)
    exponent: bounded("force exponent e (Hertz: 1.5)", minimum=1.0, maximum=MAX_CONTACT_EXPONENT, default=_LAW.exponent)
    damping: bounded("Hunt–Crossley damping d_c (s/m)", minimum=0.0, maximum=MAX_CONTACT_DAMPING, default=_LAW.damping)
    friction: bounded("Coulomb (kinetic) friction coefficient μ", minimum=0.0, maximum=MAX_FRICTION,
                      default=_LAW.friction)
    slip_velocity: bounded("regularization speed v_s of the tanh law (m/s)", minimum=MIN_SLIP_VELOCITY,
                           default=_LAW.slip_velocity)
    friction_model: Literal[FRICTION_MODELS] = Field(  # type: ignore[valid-type]
        REGULARIZED, description="regularized (tanh) or stick_slip (exact locked and sliding modes)")
    static_friction: bounded("static coefficient μ_s, ≥ friction (stick_slip only; default: friction)", minimum=0.0,
                             maximum=MAX_STATIC_FRICTION, default=None, nullable=True)
    stribeck_velocity: bounded("Stribeck velocity v_st (m/s, stick_slip only; default: none)",
                               minimum=MIN_STRIBECK_VELOCITY, maximum=MAX_STRIBECK_VELOCITY, default=None,
                               nullable=True)


Extent = pair_of("", MAX_EXTENT)


class Push(_Closed):
    """Moved by `distance` m along `direction` in `duration` s from `start` s, smooth in velocity."""

    type: Literal["push"]
    direction: pair_of("direction in the model plane (normalized; non-zero)")
    distance: bounded("distance L (m)", minimum=0.0, maximum=MAX_MOTION_EXTENT, strict=True)
    start: bounded("start time t0 (s)", minimum=0.0, maximum=MAX_MOTION_TIME)
    duration: bounded("duration T (s)", minimum=0.0, maximum=MAX_MOTION_TIME, strict=True)


class Vibration(_Closed):
    """Back and forth over `amplitude` m along `direction` at `frequency` Hz from `start` s."""

    type: Literal["vibration"]
    direction: pair_of("direction in the model plane (normalized; non-zero)")
    amplitude: bounded("amplitude A (m)", minimum=0.0, maximum=MAX_MOTION_EXTENT, strict=True)
    frequency: bounded("frequency f (Hz)", minimum=0.0, maximum=MAX_MOTION_FREQUENCY, strict=True)
    start: bounded("start time t0 (s)", minimum=0.0, maximum=MAX_MOTION_TIME)


Motion = Annotated[Push | Vibration, Field(discriminator="type")]
_Name = Annotated[str, Field(min_length=1, max_length=NAME_LENGTH, description="the object's name, unique in the scene")]


class _Object(_Closed):
    """What every object may add: its own law, its strength and its motion."""

    name: _Name
    stiffness: bounded("its own contact stiffness k_c (N/m^e), instead of model.contact's", minimum=0.0,
                       maximum=MAX_CONTACT_STIFFNESS, strict=True, default=None, nullable=True)
    damping: bounded("its own Hunt–Crossley damping d_c (s/m), instead of model.contact's", minimum=0.0,
                     maximum=MAX_CONTACT_DAMPING, default=None, nullable=True)
    break_force: bounded("normal force (N) beyond which it is crushed (default: unbreakable)", minimum=0.0,
                         strict=True, default=None, nullable=True)
    motion: Motion = Field(None, description="a prescribed motion (default: fixed in finger_base; no null)")


class CircleObject(_Object):
    """A cylinder normal to the model plane."""

    type: Literal["circle"]
    center: pair_of("centre in the model plane (m)", MAX_EXTENT)
    radius: bounded("radius R (m)", minimum=0.0, maximum=MAX_EXTENT, strict=True)


class PlaneObject(_Object):
    """A half-plane through `point` with outward `normal`; the object lies on the side of −normal."""

    type: Literal["plane"]
    point: pair_of("a point of the plane (m)", MAX_EXTENT)
    normal: pair_of("outward normal (normalized; non-zero)")


SceneObject = Annotated[CircleObject | PlaneObject, Field(discriminator="type")]
_Radius = Annotated[float, Field(gt=0.0, le=MAX_EXTENT, allow_inf_nan=False)]


def phalanx_radius_field() -> Any:
    """`model.phalanx_radius`: [ρ1, ρ3], the proximal and distal contact capsule radii (m)."""
    return (tuple[_Radius, _Radius] | None,
            Field(None, description=f"proximal, distal contact capsule radii ρ1, ρ3 (m; default {list(PHALANX_RADII)})"))


def objects_field() -> Any:
    """The `objects` key of a scene or task: a list of objects, None or [] = no contact element."""
    return (list[SceneObject] | None, Field(None, description="fixed or moving objects (spec §7)"))
