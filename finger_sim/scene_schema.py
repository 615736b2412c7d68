"""The JSON Schema of a scene file, for editors that complete and check YAML (`finger-sim schema`).

Built with pydantic from the declarations the loader itself reads: each effect's parameters
(`finger_sim.effects`' registry, bounds and defaults), the scene's own bounds (`finger_sim.scene`),
the integrators and torque profiles by name. Sections whose keys belong to elements still being
reworked (contact, the drive, objects, sensors, geometry) are checked as mappings or lists only; the
loader stays the authority on them and on the checks between keys (e.g. stops inside the range).
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from finger_sim.effects import declared_parameters
from finger_sim.inputs import PROFILES
from finger_sim.integrators import METHODS
from finger_sim.scene import (AUTO, DESCRIPTION_LENGTH, MAX_DT, MAX_RATE, MAX_TOLERANCE, MIN_TOLERANCE, NAME_LENGTH,
                              NAME_PATTERN, Scene)

#: The JSON Schema dialect pydantic writes (and the test validates with).
DIALECT = "https://json-schema.org/draft/2020-12/schema"
Number = Annotated[float, Field(allow_inf_nan=False)]
Mapping = dict[str, Any]


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


class Profile(BaseModel):
    """A torque or voltage profile: its `type` and that type's numbers (see `finger_sim.inputs`)."""

    model_config = ConfigDict(extra="allow")
    type: Literal[tuple(sorted(PROFILES))]  # type: ignore[valid-type]


class Input(_Closed):
    torque: Profile | None = Field(None, description="motor torque profile (N·m)")
    voltage: Profile | None = Field(None, description="drive voltage profile (V), with model.drive")


def _model_section() -> type[BaseModel]:
    """`model:` — every registered effect's declared parameters, plus the sections checked loosely."""
    fields: dict[str, Any] = {key: (p.annotation, p.default) for key, p in declared_parameters().items()}
    fields.update(
        joint_limits=(JointLimits | None, Field(None, description="hard MCP stops, with `restitution`")),
        geometry=(dict[str, Number] | None, Field(None, description="link lengths (m), masses (kg), inertias (kg·m²)")),
        phalanx_radius=(Number | tuple[Number, Number] | None, Field(None, description="contact capsule radii (m)")),
        contact=(Mapping | None, Field(None, description="contact law (spec §7)")),
        drive=(Mapping | None, Field(None, description="DC motor and gear (spec §8)")),
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
        objects=(list[Mapping] | None, Field(None, description="fixed or moving objects (spec §7)")),
        sensors=(Mapping | None, Field(None, description="seeded sensor models")),
    )


def scene_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scene file."""
    schema = scene_model().model_json_schema()
    return {"$schema": DIALECT, **schema, "title": "finger_sim scene"}


def schema_text(schema: dict[str, Any]) -> str:
    """A schema as the JSON file editors read."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"
