"""Node ``synth.render_suit_video``: a person in a white tight suit with coloured patches, filmed by a
known camera, written as an mp4 video, with its ground truth.

Inputs: ``motion`` (MOTION: ``joints`` (n, 16, 3) metres world, ``fps``), ``camera`` (CAMERA), optional
``suit`` (SUIT; else the ``suit`` param's file, else the default suit). Outputs: ``video`` (mp4v file,
``width`` x ``height`` at ``fps``) and ``ground_truth`` (keys, units and frames documented in
:mod:`tbha_graph.mocap.synth.groundtruth`). The image formation (depth-buffered volumes, patches on
the surface, Lambert + specular shading, background, noise, blur) is described in
:mod:`tbha_graph.mocap.synth.render`.
"""
from __future__ import annotations

from ...core.errors import NodeError
from ...core.node import node, optional
from ..ports import CAMERA, MOTION, SUIT, TRUTH, VIDEO_FILE
from ..suit import SuitSpec, load_suit
from .render import RenderParams, render_video



@node(
    "synth.render_suit_video",
    version=1,
    inputs={"motion": MOTION, "camera": CAMERA, "suit": optional(SUIT, "suit colours; default suit if unconnected")},
    outputs={"video": VIDEO_FILE, "ground_truth": TRUTH},
    params=RenderParams,
)
def render_suit_video(ctx, motion, camera, suit):
    """Render a tight-suit video of a 16-joint motion seen by a camera, with ground truth."""
    p: RenderParams = ctx.params
    if suit is not None and p.suit is not None:
        raise NodeError(
            f"a suit is connected to the 'suit' input and the 'suit' param names {p.suit}",
            hint="use one of them: disconnect the input or unset the param",
        )
    spec = suit if isinstance(suit, SuitSpec) else (SuitSpec.model_validate(suit) if suit is not None else load_suit(p.suit))
    path = ctx.output_path("video.mp4")
    gt = render_video(motion["joints"], float(motion["fps"]), camera.camera(), spec, p, path, progress=ctx.progress)
    return {"video": path, "ground_truth": gt}
