"""``segment.chroma_threshold``: plain per-colour thresholding (an alternative to ``segment.hierarchical``).

Every frame is classified whole (:class:`~tbha_graph.mocap.segment.labels.PixelClassifier`: each pixel
gets the colour whose reference chroma lies within tolerance, or the head class when dark), optionally
at reduced resolution; each colour's mask is cleaned by a morphological closing and split into
regions by their outer contours (holes inside a region, e.g. highlights, count as inside); a region's centre is its
centroid (of its convex hull by default). No temporal state: every frame is searched in full.

Output: the ``detections`` bundle (:mod:`tbha_graph.mocap.bundles.detections`), pixels of the frames
as streamed (after io.video's downscale).
"""
from __future__ import annotations

from typing import Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..bundles.colors import ColorModel, as_color_model
from .balance import apply_gains
from ..io.video import iter_frames
from ..ports import COLORS, DETECTIONS, VIDEO, VideoClip
from ..bundles.detections import DetectionBuffer
from .labels import PixelClassifier, class_regions


class ChromaThresholdParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    scale: float = Field(1.0, gt=0, le=1, description="classify frames at this fraction of their size (speed)")
    min_area: float = Field(10.0, gt=0, description="smallest region kept (full-resolution pixels²)", json_schema_extra={"unit": "px²"})
    close_px: int = Field(
        3, ge=0, le=15, description="closing kernel size filling holes (highlights) in each colour mask; 0 = off",
        json_schema_extra={"unit": "px"},
    )
    convex_hull: bool = Field(
        True, description="take each region's convex hull (fills notches highlights cut into a patch's edge)"
    )
    extra_candidates: int = Field(1, ge=0, le=8, description="candidate slots per colour beyond the joints wearing it")
    white_balance: Literal["auto", "off"] = Field(
        "auto", description="'auto': undo a coloured light or camera white balance when the suit's patches read "
        "better with the suit's white made white (tbha_graph.mocap.segment.balance; judged on the first second); 'off': never",
    )


def threshold_frame(frame: np.ndarray, classifier: PixelClassifier, params: ChromaThresholdParams):
    """Regions per class of one BGR frame: list over classes of :class:`~.labels.Regions` (full-res px)."""
    h, w = frame.shape[:2]
    if params.scale < 1.0:
        small = cv2.resize(frame, (max(1, round(w * params.scale)), max(1, round(h * params.scale))), interpolation=cv2.INTER_AREA)
        factor = w / small.shape[1]
    else:
        small, factor = frame, 1.0
    labels = classifier.labels(small)
    out = []
    for c in range(classifier.n_classes):
        regions = class_regions(labels, c, params.min_area / factor**2, close_px=params.close_px, convex=params.convex_hull)
        out.append(regions.scaled(factor) if factor != 1.0 else regions)
    return out


def segment_clip(clip: VideoClip, model: ColorModel, params: ChromaThresholdParams, progress=None,
                 log=None) -> dict[str, np.ndarray]:
    """Run the threshold segmenter over a clip; returns the detections bundle. ``log`` receives a line
    saying which white balance was used."""
    from .hierarchical import clip_balance

    classifier = PixelClassifier(model)
    balance = clip_balance(clip, model, params.white_balance, params.min_area)
    if log is not None:
        log(balance.describe())
    lut = balance.lut()
    max_k = max(len(c.joints) for c in model.classes) + params.extra_candidates
    buf = DetectionBuffer(clip.n_frames, classifier.n_classes, max_k)
    frames = iter_frames(clip)
    if progress is not None:
        frames = progress(frames, total=clip.n_frames, desc="segment")
    for row, (index, frame) in enumerate(frames):
        buf.frame_index[row] = index
        for c, r in enumerate(threshold_frame(apply_gains(frame, lut), classifier, params)):
            buf.put(row, c, r.centres, r.areas, r.boxes)
    return buf.to_arrays(model.names, clip.fps, clip.width, clip.height)


@node(
    "segment.chroma_threshold", version=2,
    inputs={"video": VIDEO, "colors": COLORS},
    outputs={"detections": DETECTIONS}, params=ChromaThresholdParams,
)
def chroma_threshold(ctx, video, colors) -> dict:
    """Find the suit's patches and the dark head in every frame by plain per-colour thresholding of the
    whole frame and connected regions (centroids); no temporal prediction."""
    clip = video if isinstance(video, VideoClip) else VideoClip.model_validate(video)
    return {"detections": segment_clip(clip, as_color_model(colors), ctx.params, progress=ctx.progress, log=ctx.log)}
