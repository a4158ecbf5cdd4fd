"""filter.fill_gaps on real motion: short gaps are interpolated, torso joints refilled rigidly, long gaps left missing."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.filter.fill_gaps import fill_gaps
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh
from tbha_graph.mocap.skeleton import JOINT_INDEX

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"


def walk():
    m = motion16_from_bvh(CLIP)
    j = m["joints"][::4][:150]  # 30 fps
    return j, {"joints": j.copy(), "fps": np.array(30.0)}


def test_short_gap_interpolated_long_gap_left_missing_and_flagged():
    truth, motion = walk()
    tracked = np.ones(truth.shape[:2], bool)
    w = JOINT_INDEX["left_wrist"]
    tracked[40:48, w] = False  # 8 frames: bridged
    tracked[80:120, w] = False  # 40 frames: too long
    motion["joints"][~tracked] += 0.3  # the solver's guesses there are bad
    motion["tracked"] = tracked
    out = run_node(fill_gaps, {"max_gap_frames": 15}, motion=motion)
    m, rep = out["motion"], out["report"]
    err = np.linalg.norm(m["joints"][40:48, w] - truth[40:48, w], axis=-1)
    assert err.max() < 0.03  # a walking wrist over 0.27 s, within 3 cm
    assert m["inferred"][40:48, w].all() and not m["inferred"][80:120, w].any()
    assert not m["tracked"][80:120, w].any()
    assert rep["inferred_samples"] == 8 and rep["missing_samples"] == 40


def test_torso_joint_refilled_rigidly_from_the_others():
    truth, motion = walk()
    tracked = np.ones(truth.shape[:2], bool)
    c = JOINT_INDEX["left_shoulder"]
    tracked[20:50, c] = False  # a 1 s gap, too long to interpolate, but the rest of the torso is seen
    motion["joints"][20:50, c] += 0.2
    motion["tracked"] = tracked
    m = run_node(fill_gaps, {"max_gap_frames": 5}, motion=motion)["motion"]
    err = np.linalg.norm(m["joints"][20:50, c] - truth[20:50, c], axis=-1)
    # a real torso is only nearly rigid (the shoulder shrugs as the arm swings): centimetres, not 20 cm
    assert err.max() < 0.03 and m["inferred"][20:50, c].all()
