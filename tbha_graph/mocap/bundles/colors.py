"""The ``colors`` port: the suit's colours in one colour space (what the ``color.*`` nodes output and
the segmenters and trackers read).

A :class:`ColorModel` lists one :class:`ColourClass` per patch colour (with the joints wearing it) plus a
last class ``"head"`` of kind ``"dark"`` for the head's dark hair. Chroma values are in the units of the
model's ``space`` (:mod:`tbha_graph.mocap.color.spaces`); how a pixel is classified and how the
tolerances are derived is :mod:`tbha_graph.mocap.color.model`. Stored as JSON.
"""
from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError

HEAD_CLASS = "head"


class ColourClass(BaseModel):
    """One class of pixels the segmenters look for."""

    name: str = Field(description="colour name from the suit spec, or 'head' for the dark head")
    kind: Literal["chroma", "dark"] = Field(description="'chroma': a patch colour; 'dark': the head's hair")
    joints: list[str] = Field(description="joints wearing this colour (same-coloured patches)")
    ref: tuple[float, float] = Field((0.0, 0.0), description="reference chroma (c1, c2), space units")
    pale: tuple[float, float] | None = Field(
        None, description="palest accepted chroma (the colour mixed with the suit's white); None = ref"
    )
    tol: float = Field(0.0, ge=0, description="tolerance radius around ref in the chroma plane, space units")


class ColorModel(BaseModel):
    """Suit colours in a colour space; see the module docstring."""

    model_config = ConfigDict(extra="forbid")

    space: Literal["rg", "hsv", "lab"] = Field(description="colour space of every chroma value")
    classes: list[ColourClass] = Field(description="patch colours, then the dark head class")
    min_luma: float = Field(ge=0, le=255, description="pixels darker than this are never patch pixels (0..255)")
    dark_max_luma: float = Field(ge=0, le=255, description="pixels darker than this are head (hair) pixels (0..255)")
    suit_ref: tuple[float, float] = Field(description="chroma of the white suit, space units")
    suit_tol: float = Field(ge=0, description="tolerance radius of the suit's white, space units")
    patch_radius: float = Field(gt=0, description="patch radius on the suit, metres (from the suit spec)")
    suit_rgb: tuple[float, float, float] = Field(
        (0.949, 0.949, 0.949), description="the suit's own colour, sRGB in [0, 1] (the white a white balance maps to)")

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.classes]

    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``ref`` (C, 2), ``pale`` (C, 2) and ``tol`` (C,) of every class (zeros for the dark class)."""
        ref = np.array([c.ref for c in self.classes], dtype=np.float64)
        pale = np.array([c.pale if c.pale is not None else c.ref for c in self.classes], dtype=np.float64)
        tol = np.array([c.tol for c in self.classes], dtype=np.float64)
        return ref, pale, tol

    def chroma_classes(self) -> list[ColourClass]:
        return [c for c in self.classes if c.kind == "chroma"]


def as_color_model(value: Any) -> ColorModel:
    """A :class:`ColorModel` as is, or built from its JSON dict (a caller outside the graph); NodeError if neither."""
    if isinstance(value, ColorModel):
        return value
    try:
        if isinstance(value, BaseModel):
            value = value.model_dump(mode="json")
        return ColorModel.model_validate(value)
    except Exception as e:
        raise NodeError(
            f"the 'colors' input is not a colour model: {e}",
            hint="connect it to the 'model' output of a color.* node (e.g. color.rg_chromaticity)",
        ) from None
