"""``color.rg_chromaticity``: the suit's colours in rg chromaticity (seed 000, eq. 1"""
from __future__ import annotations

from ...core.node import node, optional
from ..ports import COLORS, SUIT
from .model import ColorParams, color_model_node


@node("color.rg_chromaticity", version=1, inputs={"suit": optional(SUIT, "suit spec (default: the 'suit' param)")},
      outputs={"model": COLORS}, params=ColorParams)
def rg_chromaticity(ctx, suit=None) -> dict:
    """Suit colours as reference points and tolerances in the rg chroma plane, plus the dark-head and
    white-suit classes (see tbha_graph.mocap.color.model)."""
    return color_model_node(ctx, suit, "rg")
