"""The JSON Schema of a scene file, for editors that complete and check YAML (`finger-sim schema`).

Built with pydantic from the declarations the loader itself reads, field by field: each effect's
parameters (`finger_sim.effects`' registry, bounds and defaults), the contact effect's law, friction law
and objects (`effects.contact_schema`), the drive (`actuators.drive_schema`), the sensors
(`sensor_schema`), the geometry (`model.FingerParams`), the input profiles (`inputs.PROFILES`) and the
scene's own bounds (`finger_sim.scene`). The loader stays the authority on the checks between keys that
JSON Schema cannot state (e.g. stops inside the assemblable range, μ_s ≥ μ_k, a voltage only with a drive).
"""

from __future__ import annotations

import json
from dataclasses import MISSING, fields
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, create_model

from finger_sim.actuators.drive_schema import DriveSchema
from finger_sim.effects import declared_parameters
from finger_sim.effects.contact_schema import ContactLaw, objects_field, phalanx_radius_field
from finger_sim.effects.parameters import bounded, pair_of
from finger_sim.inputs import _LIMITS, MAX_TORQUE, PROFILES
from finger_sim.model import FingerParams
from finger_sim.sensor_schema import sensors_model
from finger_sim.tip_force_profile import MAX_SPAN_FORCE, MAX_SPANS
from finger_sim.integrators import METHODS
from finger_sim.scene import (AUTO, DESCRIPTION_LENGTH, MAX_DT, MAX_RATE, MAX_TOLERANCE, MIN_TOLERANCE, NAME_LENGTH,
                              NAME_PATTERN, Scene)

#: The JSON Schema dialect pydantic writes (and the test validates with).
DIALECT = "https://json-schema.org/draft/2020-12/schema"
Number = Annotated[float, Field(allow_inf_nan=False)]


class _Closed(BaseModel):
    """A section whose keys are all known: any other key is an error, as in the loader."""

    model_config = ConfigDict(extra="forbid")


class JointLimits(_Closed):
    mcp: tuple[Number, Number] = Field(description="MCP stops [lower, upper] (rad), inside the assemblable range")


class Initial(_Closed):
    theta1: Number = Field(Scene.theta1, description="initial MCP angle θ1 (rad)")
    theta1_dot: Annotated[float, Field(ge=-MAX_RATE, le=MAX_RATE)] = Field(Scene.theta1_dot,
                                                                          description="initial θ1' (rad/s)")


class Integrator(_Closed):
    method: Literal[tuple(sorted([*METHODS, AUTO]))] = Field(Scene.method, description="integration method")  # type: ignore[valid-type]
    dt: Annotated[float, Field(gt=0.0, le=MAX_DT)] = Field(Scene.dt, description="output step (s)")
    tolerance: Annotated[float, Field(ge=MIN_TOLERANCE, le=MAX_TOLERANCE)] = Field(
        Scene.tolerance, description="global θ error that `method: auto` delivers (rad)")


def _profile(kind: str) -> type[BaseModel]:
    """One profile type of `finger_sim.inputs.PROFILES`: its `type` and its numbers, bounded as the loader
    bounds them (magnitude ≤ MAX_TORQUE, slope ≤ MAX_SLOPE, frequency > 0)."""
    numbers: dict[str, Any] = {}
    for f in fields(PROFILES[kind]):
        limit = _LIMITS.get(f.name, MAX_TORQUE)
        low = {"gt": 0.0} if f.name == "frequency" else {} if limit == float("inf") else {"ge": -limit}
        numbers[f.name] = (Annotated[float, Field(le=limit, allow_inf_nan=False, **low)],
                           ... if f.default is MISSING else f.default)
    return create_model(kind.capitalize(), __base__=_Closed, type=(Literal[kind], ...), **numbers)


#: A torque or voltage profile, told apart by its `type`.
Profile = Annotated[Union[tuple(_profile(k) for k in sorted(PROFILES))], Field(discriminator="type")]  # noqa: UP007


class TipForceSpan(_Closed):
    start: bounded("start (s), within the duration", minimum=0.0)
    end: bounded("end (s), after start, within the duration (default: the duration)", minimum=0.0, default=None)
    force: pair_of("fingertip force over [start, end) (N, model plane)", MAX_SPAN_FORCE)


class Input(_Closed):
    torque: Profile | None = Field(None, description="motor torque profile (N·m); not with model.drive")
    voltage: Profile | None = Field(None, description="drive voltage profile (V), with model.drive only")
    tip_force: Annotated[list[TipForceSpan], Field(max_length=MAX_SPANS)] | None = Field(
        None, description="spans over which a force replaces model.tip_force (not overlapping)")


def _geometry() -> type[BaseModel]:
    """`model.geometry`: any field of `FingerParams` (the loader checks the linkage assembles)."""
    return create_model("Geometry", __base__=_Closed,
                        **{f.name: (Number, Field(f.default)) for f in fields(FingerParams)})


def _model_section() -> type[BaseModel]:
    """`model:` — every registered effect's declared parameters, plus the sections checked loosely."""
    fields: dict[str, Any] = {key: (p.annotation, p.default) for key, p in declared_parameters().items()}
    fields.update(
        joint_limits=(JointLimits | None, Field(None, description="hard MCP stops, with `restitution`")),
        geometry=(_geometry() | None, Field(None, description="FingerParams overrides: lengths (m), masses (kg), "
                                                          "inertias (kg·m²), angles (rad)")),
        phalanx_radius=phalanx_radius_field(),
        contact=(ContactLaw | None, Field(None, description="contact law (spec §7)")),
        drive=(DriveSchema | None, Field(None, description="DC motor and gear (spec §8); {} = its defaults")),
    )
    return create_model("Model", __base__=_Closed, **fields)


def scene_model() -> type[BaseModel]:
    """The pydantic model of a scene file."""
    return create_model(
        "Scene",
        __base__=_Closed,
        name=(Annotated[str, Field(pattern=f"^{NAME_PATTERN.pattern}$", max_length=NAME_LENGTH)], Scene.name),
        description=(Annotated[str, Field(max_length=DESCRIPTION_LENGTH)], ""),
        model=(_model_section() | None, None),
        input=(Input | None, None),
        initial=(Initial | None, None),
        duration=(Annotated[float, Field(gt=0.0, allow_inf_nan=False)], Scene.duration),
        integrator=(Integrator | None, None),
        objects=objects_field(),
        sensors=(sensors_model() | None, Field(None, description="seeded sensor models (finger_sim.sensors)")),
    )


def scene_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scene file."""
    schema = scene_model().model_json_schema()
    return {"$schema": DIALECT, **schema, "title": "finger_sim scene"}


def schema_text(schema: dict[str, Any]) -> str:
    """A schema as the JSON file editors read."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"
