"""``segment.hierarchical``: the seed's hierarchical patch tracker (default segmenter).

Per frame, every patch region being followed ("blob") is searched only in a window around its
constant-velocity prediction and located there by :func:`~tbha_graph.mocap.segment.refine.refine_windows`
(adaptive chroma clustering ∪ Roberts edges, boundary histogram peaks). A whole-frame search at reduced
resolution (:class:`~tbha_graph.mocap.segment.labels.PixelClassifier`) runs on the first frame, when a
colour has fewer blobs than joints wearing it (a patch was lost: every ``lost_search_every`` frames), and
every ``full_search_every`` frames; the regions it finds that no blob covers become new blobs, refined in
the same frame.

Output: the ``detections`` bundle (:mod:`tbha_graph.mocap.bundles.detections`), centres in pixels of
the video frames as streamed (after io.video's downscale).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.node import node
from ..bundles.colors import ColorModel, as_color_model
from .balance import Balance, apply_gains, choose_balance
from ..io.video import iter_frames
from ..ports import COLORS, DETECTIONS, VIDEO, VideoClip
from ..bundles.detections import DetectionBuffer
from .labels import PixelClassifier, class_regions
from .refine import RefineSettings, refine_windows, window_origins


class HierarchicalParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    search_scale: float = Field(
        0.5, gt=0, le=1, description="resolution of the whole-frame search, as a fraction of the frame size"
    )
    min_area: float = Field(
        10.0, gt=0, description="smallest patch region kept", json_schema_extra={"unit": "px²"}
    )
    extra_candidates: int = Field(
        1, ge=0, le=8, description="candidate slots per colour beyond the number of joints wearing it"
    )
    window_scale: float = Field(
        3.0, ge=1.5, le=10, description="search window side as a multiple of the patch's diameter"
    )
    min_window: int = Field(32, ge=8, le=512, description="smallest search window side", json_schema_extra={"unit": "px"})
    max_window: int = Field(128, ge=8, le=1024, description="largest search window side", json_schema_extra={"unit": "px"})
    cluster_sigma: float = Field(
        3.0, gt=0.5, le=10, description="adaptive clustering gate, in Mahalanobis units of the colour's spread"
    )
    cluster_iterations: int = Field(2, ge=1, le=10, description="mean/covariance re-estimations per window")
    edge_fraction: float = Field(
        0.3, gt=0, lt=1, description="Roberts edge threshold as a fraction of the strongest edge near the patch"
    )
    edge_band: int = Field(
        2, ge=0, le=10, description="edges are kept this close to the clustered region", json_schema_extra={"unit": "px"}
    )
    peak_fraction: float = Field(
        0.3, gt=0, le=1, description="a boundary-histogram peak must hold this fraction of the highest bin"
    )
    centre: Literal["rectangle", "centroid"] = Field(
        "rectangle",
        description="patch centre: 'rectangle' = centre of the boundary-histogram rectangle (seed 000); "
        "'centroid' = centroid of the merged region",
    )
    lost_search_every: int = Field(
        2, ge=1, description="while a patch is lost, search the whole frame every this many frames",
        json_schema_extra={"unit": "frame"},
    )
    white_balance: Literal["auto", "off"] = Field(
        "auto", description="'auto': undo a coloured light or camera white balance when the suit's patches read "
        "better with the suit's white made white (tbha_graph.mocap.segment.balance; judged on the first second); 'off': never",
    )
    full_search_every: int = Field(
        0, ge=0, description="search the whole frame every this many frames anyway (0 = only when lost)",
        json_schema_extra={"unit": "frame"},
    )

    @model_validator(mode="after")
    def _windows(self) -> "HierarchicalParams":
        if self.min_window > self.max_window:
            raise ValueError(f"min_window ({self.min_window}) must not exceed max_window ({self.max_window})")
        return self


@dataclass
class _Blob:
    """A patch region being followed: its class, position and velocity (px, px/frame), size (px)."""

    cls: int
    pos: np.ndarray  # (2,) px
    vel: np.ndarray = field(default_factory=lambda: np.zeros(2))
    diameter: float = 0.0
    area: float = 0.0
    box: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))


def _even(x: float, lo: int, hi: int) -> int:
    v = int(np.clip(np.ceil(x), lo, hi))
    return v + (v % 2)


class HierarchicalSegmenter:
    """Frame-by-frame state of ``segment.hierarchical`` (usable without the node: :meth:`process`)."""

    def __init__(self, model: ColorModel, params: HierarchicalParams, width: int, height: int):
        self.model = model
        self.p = params
        self.width, self.height = width, height
        self.classifier = PixelClassifier(model)
        self.n_classes = len(model.classes)
        self.expected = [len(c.joints) for c in model.classes]
        self.max_k = max(self.expected) + params.extra_candidates
        self.dark = [c.kind == "dark" for c in model.classes]
        self.settings = RefineSettings(
            cluster_sigma=params.cluster_sigma, cluster_iterations=params.cluster_iterations,
            edge_fraction=params.edge_fraction, edge_band=params.edge_band, peak_fraction=params.peak_fraction,
            min_area=params.min_area, centre=params.centre,
        )
        self.blobs: list[_Blob] = []
        self.window = {False: params.min_window, True: params.min_window}  # by "is dark class"
        self.frames_seen = 0
        self.last_lost_search = -(10**9)

    # --- whole-frame search -------------------------------------------------------------------
    def _search(self, frame: np.ndarray, classes: list[int]) -> list[_Blob]:
        s = self.p.search_scale
        if s < 1.0:
            small = cv2.resize(frame, (max(1, round(self.width * s)), max(1, round(self.height * s))), interpolation=cv2.INTER_AREA)
            factor = self.width / small.shape[1]
        else:
            small, factor = frame, 1.0
        labels = self.classifier.labels(small)
        new: list[_Blob] = []
        for c in classes:
            regions = class_regions(labels, c, self.p.min_area / factor**2)
            if factor != 1.0:
                regions = regions.scaled(factor)
            have = [b for b in self.blobs if b.cls == c]
            room = self.max_k - len(have)
            for k in np.argsort(-regions.areas):
                if room <= 0:
                    break
                pos = regions.centres[k]
                diam = float(np.sqrt(regions.areas[k] * 4.0 / np.pi))
                if any(np.linalg.norm(b.pos - pos) < max(b.diameter, diam, 4.0) for b in have):
                    continue
                blob = _Blob(c, pos.astype(np.float64), diameter=diam)
                have.append(blob)
                new.append(blob)
                room -= 1
        return new

    def _update_windows(self) -> None:
        for dark in (False, True):
            d = [b.diameter for b in self.blobs if self.dark[b.cls] == dark and b.diameter > 0]
            if d:
                self.window[dark] = _even(self.p.window_scale * float(np.median(d)), self.p.min_window, min(self.p.max_window, self.width, self.height))

    # --- window refinement ----------------------------------------------------------------------
    def _refine(self, frame: np.ndarray, blobs: list[_Blob], predicted: np.ndarray, moving: bool = True) -> np.ndarray:
        """Refine ``blobs`` around ``predicted`` (n, 2); updates them in place (velocity too when ``moving``);
        returns ok (n,)."""
        ok = np.zeros(len(blobs), bool)
        for dark in (False, True):
            idx = [i for i, b in enumerate(blobs) if self.dark[b.cls] == dark]
            if not idx:
                continue
            size = self.window[dark]
            pred = predicted[idx]
            origins = window_origins(pred, size, self.width, self.height)
            classes = [blobs[i].cls for i in idx]
            res = refine_windows(frame, origins, size, pred, classes, self.classifier, self.settings)
            # a region cut by the window border: look again in a window centred on what was found
            again = np.flatnonzero(res.ok & res.touches)
            if again.size:
                o2 = window_origins(res.centres[again], size, self.width, self.height)
                r2 = refine_windows(frame, o2, size, res.centres[again], [classes[i] for i in again], self.classifier, self.settings)
                for j, a in enumerate(again):
                    if r2.ok[j]:
                        res.centres[a], res.boxes[a], res.areas[a] = r2.centres[j], r2.boxes[j], r2.areas[j]
                        res.diameters[a] = r2.diameters[j]
            for j, i in enumerate(idx):
                if not res.ok[j]:
                    continue
                b = blobs[i]
                b.vel = res.centres[j] - b.pos if moving else np.zeros(2)
                b.pos = res.centres[j].copy()
                b.diameter = float(res.diameters[j])
                b.area, b.box = float(res.areas[j]), res.boxes[j].copy()
                ok[i] = True
        return ok

    def _dedupe(self, blobs: list[_Blob]) -> list[_Blob]:
        """Drop a blob that landed on the same region as an earlier one of its colour (patches merged)."""
        kept: list[_Blob] = []
        for b in blobs:
            bx, by = float(b.pos[0]), float(b.pos[1])
            if any(
                k.cls == b.cls and (float(k.pos[0]) - bx) ** 2 + (float(k.pos[1]) - by) ** 2 < (0.5 * max(k.diameter, b.diameter, 2.0)) ** 2
                for k in kept
            ):
                continue
            kept.append(b)
        return kept

    def process(self, frame: np.ndarray) -> list[tuple[int, np.ndarray, float, np.ndarray]]:
        """Process the next frame; returns ``(class, centre (2,), area, box (4,))`` per found patch region."""
        t = self.frames_seen
        self.frames_seen += 1
        # 1. follow existing blobs in windows around their predictions
        if self.blobs:
            pred = np.array([b.pos + b.vel for b in self.blobs])
            ok = self._refine(frame, self.blobs, pred)
            self.blobs = self._dedupe([b for b, k in zip(self.blobs, ok) if k])
        # 2. whole-frame search when needed
        counts = np.bincount([b.cls for b in self.blobs], minlength=self.n_classes)
        lost = [c for c in range(self.n_classes) if counts[c] < self.expected[c]]
        periodic = self.p.full_search_every > 0 and t % self.p.full_search_every == 0
        due = lost and (t - self.last_lost_search >= self.p.lost_search_every)
        if t == 0 or periodic or due:
            if due:
                self.last_lost_search = t
            classes = list(range(self.n_classes)) if (t == 0 or periodic) else lost
            new = self._search(frame, classes)
            if new:
                if not self.blobs:
                    self.blobs = list(new)
                    self._update_windows()  # size the windows from the regions just found
                else:
                    self.blobs.extend(new)
                new_ok = self._refine(frame, new, np.array([b.pos for b in new]), moving=False)
                failed = {id(b) for b, k in zip(new, new_ok) if not k}
                self.blobs = self._dedupe([b for b in self.blobs if id(b) not in failed])
            if periodic or t == 0:
                self._update_windows()
        return [(b.cls, b.pos, b.area, b.box) for b in self.blobs]


def clip_balance(clip: VideoClip, model: ColorModel, mode: str, min_area: float = 10.0, samples: int = 4) -> Balance:
    """The white balance of ``clip`` for ``model`` (:func:`~tbha_graph.mocap.segment.balance.choose_balance`),
    judged on ``samples`` frames spread over the clip's first second; none when ``mode`` is ``'off'``."""
    if mode == "off":
        return Balance(None)
    span = max(1, int(round(clip.fps)))
    step = max(1, span // max(1, samples - 1))
    frames = [f for i, (_, f) in enumerate(iter_frames(clip, clip.start, min(clip.stop, clip.start + span + 1))) if i % step == 0]
    return choose_balance(frames[:samples], model, min_area)


def segment_clip(clip: VideoClip, model: ColorModel, params: HierarchicalParams, progress=None,
                 log=None) -> dict[str, np.ndarray]:
    """Run the hierarchical segmenter over a clip; returns the detections bundle. ``log`` receives a line
    saying which white balance was used."""
    seg = HierarchicalSegmenter(model, params, clip.width, clip.height)
    buf = DetectionBuffer(clip.n_frames, seg.n_classes, seg.max_k)
    balance = clip_balance(clip, model, params.white_balance, params.min_area)
    if log is not None:
        log(balance.describe())
    lut = balance.lut()
    frames = iter_frames(clip)
    if progress is not None:
        frames = progress(frames, total=clip.n_frames, desc="segment")
    for row, (index, frame) in enumerate(frames):
        buf.frame_index[row] = index
        found = seg.process(apply_gains(frame, lut))
        for c in range(seg.n_classes):
            mine = [f for f in found if f[0] == c]
            if mine:
                buf.put(row, c, np.array([f[1] for f in mine]), np.array([f[2] for f in mine]), np.array([f[3] for f in mine]))
    return buf.to_arrays(model.names, clip.fps, clip.width, clip.height)


@node(
    "segment.hierarchical", version=2,
    inputs={"video": VIDEO, "colors": COLORS},
    outputs={"detections": DETECTIONS}, params=HierarchicalParams,
)
def hierarchical(ctx, video, colors) -> dict:
    """Find the suit's patches and the dark head in every frame: seed 000's hierarchical tracking
    (adaptive colour clustering ∪ Roberts edges, boundary-histogram rectangle) in windows around
    each patch's predicted position; whole-frame search at reduced resolution only when needed."""
    clip = video if isinstance(video, VideoClip) else VideoClip.model_validate(video)
    return {"detections": segment_clip(clip, as_color_model(colors), ctx.params, progress=ctx.progress, log=ctx.log)}
