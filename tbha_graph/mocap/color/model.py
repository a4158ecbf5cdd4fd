"""The colour model: the suit's colours expressed in one colour space (what the ``color.*`` nodes output).

A :class:`ColorModel` lists one :class:`ColourClass` per patch colour (with the joints wearing it) plus
a last class ``"head"`` of kind ``"dark"`` for the head's dark hair (seed 000: the head's "black patch").
Each patch colour has a reference point ``ref`` in the space's chroma plane (see
:mod:`tbha_graph.mocap.color.spaces`), a "pale" point ``pale`` part of the way from ``ref`` towards the
suit's white (a patch under a specular sheen, or with a channel clipped, is the colour mixed with
white, whose chromaticity lies on the ray from the white through ``ref``), and a tolerance ``tol`` in
the same units. A pixel belongs to the colour when its chroma lies in the colour's wedge
(:func:`~tbha_graph.mocap.color.spaces.wedge_distance_sq`: along the ray from ``pale`` to ``tol``
beyond ``ref``, within ``tol`` of the ray at ``ref``, proportionally less towards the white), not
within ``suit_tol`` of the suit's white ``suit_ref``, and its luma is at least ``min_luma`` (darker
pixels have unreliable chroma). A pixel that is no patch colour is "dark" (head) when its luma is below
``dark_max_luma``.

Tolerances are derived from the suit: ``tol = tolerance_scale * (distance to the nearest other colour
or to the suit's white) / 2``, so the saturated ends of the colour regions never overlap while
``tolerance_scale <= 1``; nor do the wedges, which narrow towards the white (where they would meet, a
pixel goes to the nearest).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath
from ..bundles.colors import HEAD_CLASS, ColorModel, ColourClass
from ..suit import SuitSpec, load_suit
from .spaces import rgb_to_chroma


class ColorParams(BaseModel):
    """Params shared by the ``color.*`` nodes."""

    model_config = ConfigDict(extra="forbid")

    suit: InputPath | None = Field(
        None, description="suit spec YAML; ignored when the 'suit' input is connected; None = the default suit"
    )
    tolerance_scale: float = Field(
        0.9, gt=0, le=1.0,
        description="tolerance radius as a fraction of half the chroma distance to the nearest other colour",
    )
    desaturation: float = Field(
        0.55, ge=0, lt=1,
        description="how far from a colour towards the suit's white its pixels may lie (sheen, highlights, clipping)",
    )
    min_luma: float = Field(
        30.0, ge=0, le=255, description="darker pixels are not classified as patch colours",
        json_schema_extra={"unit": "grey level"},
    )
    dark_max_luma: float = Field(
        45.0, ge=0, le=255, description="pixels darker than this are the head's hair",
        json_schema_extra={"unit": "grey level"},
    )


def build_color_model(space: str, suit: SuitSpec, tolerance_scale: float = 0.9, min_luma: float = 30.0,
                      dark_max_luma: float = 45.0, desaturation: float = 0.55) -> ColorModel:
    """The colour model of ``suit`` in ``space`` (``"rg"``, ``"hsv"`` or ``"lab"``).

    References are the suit's sRGB colours converted with the same function the segmenters use.
    Raises :class:`NodeError` when two colours (or a colour and the suit) have the same chroma.
    """
    by_colour = suit.joints_by_colour()
    names = list(by_colour)
    refs = rgb_to_chroma(space, np.stack([suit.rgb(n) for n in names]))  # (n, 2)
    suit_hex = suit.suit_color.lstrip("#")
    suit_rgb = np.array([int(suit_hex[i : i + 2], 16) for i in (0, 2, 4)], dtype=np.float64) / 255.0
    suit_ref = rgb_to_chroma(space, suit_rgb[None])[0]
    pts = np.vstack([refs, suit_ref[None]])
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    nearest = d.min(axis=1)
    if not np.all(nearest > 1e-6):
        i = int(np.argmin(nearest[:-1])) if nearest[:-1].min() <= 1e-6 else len(names)
        j = int(np.argmin(d[i]))
        label = lambda k: names[k] if k < len(names) else "the suit"  # noqa: E731
        raise NodeError(
            f"suit colours {label(i)} and {label(j)} have the same chroma in the {space} space: they cannot be told apart",
            hint="give the suit clearly different colours (different hue/saturation, not just brightness)",
        )
    tols = tolerance_scale * nearest / 2.0
    pales = refs + desaturation * (suit_ref[None] - refs)
    classes = [
        ColourClass(
            name=n, kind="chroma", joints=by_colour[n], ref=(float(refs[k, 0]), float(refs[k, 1])),
            pale=(float(pales[k, 0]), float(pales[k, 1])), tol=float(tols[k]),
        )
        for k, n in enumerate(names)
    ]
    classes.append(ColourClass(name=HEAD_CLASS, kind="dark", joints=["head"]))
    return ColorModel(
        space=space, classes=classes, min_luma=float(min_luma), dark_max_luma=float(dark_max_luma),
        suit_ref=(float(suit_ref[0]), float(suit_ref[1])), suit_tol=float(tols[-1]), patch_radius=float(suit.patch_radius),
        suit_rgb=tuple(float(x) for x in suit_rgb),
    )


def color_model_node(ctx: Any, suit: SuitSpec | None, space: str) -> dict:
    """Shared body of the ``color.*`` nodes: the connected suit, else the ``suit`` param, else the default."""
    p: ColorParams = ctx.params
    if suit is None:
        suit = load_suit(p.suit)
    elif not isinstance(suit, SuitSpec):
        suit = SuitSpec.model_validate(suit)
    return {"model": build_color_model(space, suit, p.tolerance_scale, p.min_luma, p.dark_max_luma, p.desaturation)}
