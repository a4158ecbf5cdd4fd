"""segment.chunked: frame chunks segmented in parallel give the sequential run's detections, locally and on Dask."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity
from tbha_graph.mocap.io.video import probe_video
from tbha_graph.mocap.segment.chroma_threshold import chroma_threshold
from tbha_graph.mocap.segment.chunked import chunk_ranges, chunked
from tbha_graph.mocap.segment.hierarchical import hierarchical

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "data" / "sample" / "sample.mp4"
KEYS = ("centres", "areas", "boxes", "frame_index")


def same(a, b):
    return all(np.array_equal(a[k], b[k], equal_nan=True) for k in KEYS)


@pytest.fixture(scope="module")
def inputs():
    return probe_video(SAMPLE), run_node(rg_chromaticity, {})["model"]


def test_chunk_ranges_cover_the_clip_once():
    r = chunk_ranges(10, 250, 100, 30)
    assert r == [(10, 110, 10), (80, 210, 110), (180, 250, 210)]


@pytest.mark.parametrize("method,seq", [("chroma_threshold", chroma_threshold), ("hierarchical", hierarchical)])
def test_chunked_equals_sequential(inputs, method, seq):
    clip, model = inputs
    a = run_node(seq, {}, video=clip, colors=model)["detections"]
    b = run_node(chunked, {"method": method, "chunk_frames": 60, "workers": 2}, video=clip, colors=model)["detections"]
    assert b["centres"].shape == a["centres"].shape and same(a, b)


def test_chunked_inside_a_dask_pipeline(tmp_path, inputs):
    pytest.importorskip("distributed")
    from tbha_graph.core import Cache, Pipeline

    clip, model = inputs
    p = Pipeline()
    p.add("decode", "io.video", params={"path": str(SAMPLE), "stop": 120})
    p.add("colors", "color.rg_chromaticity")
    p.add("segment", "segment.chunked", video="decode.video", colors="colors.model",
          params={"method": "chroma_threshold", "chunk_frames": 40})
    p.output("detections.npz", "segment.detections")
    run = p.run(cache=Cache(tmp_path / "c"), executor="dask", workers=2)
    seq = run_node(chroma_threshold, {}, video=clip.model_copy(update={"stop": 120}), colors=model)["detections"]
    assert same(run.output("detections.npz"), seq)


def test_bad_options_are_refused_before_running():
    with pytest.raises(ValidationError, match=r"search_scale\n  Input should be less than or equal to 1"):
        run_node(chunked, {"method": "hierarchical", "options": {"search_scale": 5}})
