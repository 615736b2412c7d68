"""The JSON Schema of a task file (`finger-sim schema --task`), from `tasks.schema`'s own bounds.

The loader (`tasks.schema.load_task`) stays the authority on what depends on the scene it names:
times within the duration, setpoints increasing from 0, disturbances that do not overlap, the
controller's input matching the scene's.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from finger_sim.effects.contact_schema import objects_field
from finger_sim.effects.parameters import bounded, pair_of, whole
from finger_sim.scene import NAME_LENGTH
from finger_sim.scene_schema import DIALECT
from finger_sim.tasks.metrics import BOOLEAN_METRICS, METRICS
from finger_sim.tasks.schema import (HOLD_AFTER, INPUTS, MAX_DURATION, MAX_EVENTS, MAX_FORCE, MAX_STEPS,
                                     TEXT_LENGTH)


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Controller(_Closed):
    sample_steps: whole("steps of the scene's dt between controller samples", 1, MAX_STEPS, default=1)
    delay_steps: whole("steps of delay before a command acts", 0, MAX_STEPS, default=1)
    input: Literal[INPUTS] | None = Field(None, description="the scene input the controller commands (default: the scene's)")  # type: ignore[valid-type]


class Setpoint(_Closed):
    t: bounded("from this time on (s), increasing, the first at 0", minimum=0.0)
    value: bounded("grip-force setpoint (N)", minimum=0.0, maximum=MAX_FORCE)


class Disturbance(_Closed):
    type: Literal["tip_force"]
    start: bounded("start (s), within the duration", minimum=0.0)
    end: bounded("end (s), after start (default: the duration)", minimum=0.0, default=None)
    force: pair_of("tip force over [start, end) (N, model plane)", MAX_FORCE)


def _limits() -> type[BaseModel]:
    """`limits`: each metric's largest passing value (a number ≥ 0), or a boolean metric's passing value."""
    fields: dict[str, Any] = {}
    for key, (unit, text) in METRICS.items():
        if key in BOOLEAN_METRICS:
            fields[key] = (bool | None, Field(None, description=f"the passing value of: {text}"))
        else:
            fields[key] = (bounded(f"largest passing {text} ({unit})", minimum=0.0, default=None), None)
    return create_model("Limits", __base__=_Closed, **fields)


def task_model() -> type[BaseModel]:
    """The pydantic model of a task file."""
    events = {"max_length": MAX_EVENTS}
    return create_model(
        "Task",
        __base__=_Closed,
        name=(Annotated[str, Field(max_length=NAME_LENGTH)], Field(None, description="default: the file's stem")),
        description=(Annotated[str, Field(max_length=TEXT_LENGTH)], ""),
        scene=(Annotated[str, Field(max_length=TEXT_LENGTH, description="the scene file, relative to the task file")],
               ...),
        objects=objects_field(),
        duration=(bounded("duration (s), replaces the scene's", minimum=0.0, maximum=MAX_DURATION, strict=True,
                          default=None), None),
        controller=(Controller | None, None),
        setpoints=(Annotated[list[Setpoint], Field(min_length=1, **events)], ...),
        disturbances=(Annotated[list[Disturbance], Field(**events)] | None, None),
        hold_after=(bounded("the holding window starts this long after each setpoint change (s)", minimum=0.0,
                            maximum=MAX_DURATION, default=HOLD_AFTER), HOLD_AFTER),
        limits=(_limits() | None, None),
    )


def task_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a task file."""
    return {"$schema": DIALECT, **task_model().model_json_schema(), "title": "finger_sim task"}
