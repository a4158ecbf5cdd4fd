"""``segment.chunked``: a per-frame segmenter run on frame chunks in parallel, then stitched.

Decoding and segmenting are per-frame work; tracking and reconstruction that follow are sequential.
For a long take this node splits the clip into chunks of ``chunk_frames``, segments each chunk in its
own process (a local process pool, or the Dask cluster when the pipeline runs on one: ``--executor
dask``), and concatenates the detections in frame order. Each process streams its own frame range, so
memory per worker is bounded by the chunk, not the take.

The result equals the sequential segmenter's:

* ``chroma_threshold`` looks at each frame alone: chunks change nothing.
* ``hierarchical`` searches windows around predictions from earlier frames, so each chunk starts
  ``warmup_frames`` early (a whole-frame search, then tracking) and those frames are dropped; once its
  windows have locked on, the search state no longer depends on where it began. On the bundled
  sample, 60 warm-up frames give detections identical to the sequential run (30 left a different spare
  candidate in 2 of 1,890 frame-colour cells; the tracks were identical even then). The test checks it.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.node import node
from ..bundles.colors import as_color_model
from ..ports import COLORS, DETECTIONS, VIDEO, VideoClip
from . import chroma_threshold as _thr
from . import hierarchical as _hier

SEGMENTERS = {
    "hierarchical": (_hier.segment_clip, _hier.HierarchicalParams),
    "chroma_threshold": (_thr.segment_clip, _thr.ChromaThresholdParams),
}


class ChunkedParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    method: Literal["hierarchical", "chroma_threshold"] = Field("hierarchical", description="the per-frame segmenter to run on each chunk")
    options: dict[str, Any] = Field(default_factory=dict, description="params of that segmenter (see `tbha-graph nodes segment.<method>`)")
    chunk_frames: int = Field(300, ge=10, description="frames per chunk", json_schema_extra={"unit": "frame"})
    warmup_frames: int = Field(60, ge=0, description="frames segmented before each chunk and dropped (hierarchical)", json_schema_extra={"unit": "frame"})
    workers: int = Field(2, ge=1, le=64, description="processes for the chunks when not running on a Dask cluster")

    @model_validator(mode="after")
    def _options(self) -> "ChunkedParams":
        SEGMENTERS[self.method][1].model_validate(self.options)  # refuse bad options before running
        return self


def _segment_range(method: str, options: dict, clip_json: dict, model_json: dict, start: int, stop: int, keep_from: int) -> dict:
    """Segment frames [start, stop) of the clip; return the rows from ``keep_from`` on (runs in a worker)."""
    fn, params_model = SEGMENTERS[method]
    clip = VideoClip.model_validate({**clip_json, "start": start, "stop": stop})
    det = fn(clip, as_color_model(model_json), params_model.model_validate(options))
    drop = keep_from - start
    return {k: (v[drop:] if isinstance(v, np.ndarray) and v.ndim and k in ("centres", "areas", "boxes", "frame_index") else v)
            for k, v in det.items()}


def chunk_ranges(start: int, stop: int, size: int, warmup: int) -> list[tuple[int, int, int]]:
    """``(segment_from, stop, keep_from)`` per chunk covering [start, stop)."""
    out = []
    for s in range(start, stop, size):
        out.append((max(start, s - warmup), min(stop, s + size), s))
    return out


def _run_chunks(tasks: list[tuple], workers: int) -> list[dict]:
    try:  # inside a Dask worker: use the cluster
        from distributed import get_worker, worker_client

        get_worker()
        with worker_client() as client:
            return client.gather([client.submit(_segment_range, *t, pure=False) for t in tasks])
    except (ImportError, ValueError):
        pass
    if workers == 1 or len(tasks) == 1:
        return [_segment_range(*t) for t in tasks]
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
        return list(pool.map(_segment_range, *zip(*tasks)))


@node(
    "segment.chunked", version=1,
    inputs={"video": VIDEO, "colors": COLORS},
    outputs={"detections": DETECTIONS}, params=ChunkedParams,
)
def chunked(ctx, video, colors) -> dict:
    """A segmenter (hierarchical or chroma_threshold) run on frame chunks in parallel; same detections as running it straight through."""
    p: ChunkedParams = ctx.params
    clip = video if isinstance(video, VideoClip) else VideoClip.model_validate(video)
    model = as_color_model(colors)
    warm = p.warmup_frames if p.method == "hierarchical" else 0
    tasks = [(p.method, p.options, clip.model_dump(), model.model_dump(), a, b, keep)
             for a, b, keep in chunk_ranges(clip.start, clip.stop, p.chunk_frames, warm)]
    parts = _run_chunks(tasks, p.workers)
    out = dict(parts[0])
    for key in ("centres", "areas", "boxes", "frame_index"):
        out[key] = np.concatenate([part[key] for part in parts], axis=0)
    return {"detections": out}
