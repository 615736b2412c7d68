"""The JSON Schema of a hand file (`finger-sim schema --hand`), from `hand_config`'s own bounds.

The loader (`hand_config.load_hand`) stays the authority: it also resolves each scene and checks
that names and frame prefixes differ between fingers.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from finger_sim.runtime.hand_config import MAX_ANGLE, MAX_FINGERS, MAX_OFFSET, NAME
from finger_sim.scene_schema import DIALECT

Offset = Annotated[float, Field(ge=-MAX_OFFSET, le=MAX_OFFSET, allow_inf_nan=False)]
Angle = Annotated[float, Field(ge=-MAX_ANGLE, le=MAX_ANGLE, allow_inf_nan=False)]


class Finger(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: Annotated[str, Field(pattern=f"^{NAME.pattern}$", description="namespace of the finger's topics")]
    scene: Annotated[str, Field(min_length=1, description="an installed scene's name, or a path (relative: to the hand file)")]
    pose: tuple[Offset, Offset, Offset, Angle, Angle, Angle] = Field(
        (0.0,) * 6, description="base pose in hand_base: x, y, z (m), roll, pitch, yaw (rad), as a URDF origin")
    frame_prefix: Annotated[str, Field(pattern=r"^\S*$")] = Field(
        None, description="prefix of its links, joints and frames (default: the name and '_')")  # type: ignore[assignment]


class Hand(BaseModel):
    model_config = ConfigDict(extra="forbid")
    fingers: Annotated[list[Finger], Field(min_length=1, max_length=MAX_FINGERS)]


def hand_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a hand file."""
    return {"$schema": DIALECT, **Hand.model_json_schema(), "title": "finger_sim hand"}
