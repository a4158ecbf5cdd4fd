"""MOTION filters: filter.butterworth, filter.one_euro, filter.bone_length, filter.none."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.filter.bone_length import bone_length
from tbha_graph.mocap.filter.butterworth import butterworth
from tbha_graph.mocap.filter.none import none
from tbha_graph.mocap.filter.one_euro import one_euro
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
FPS = 120.0


def motion(joints, fps=FPS, **extra):
    return {"joints": np.asarray(joints, dtype=np.float64), "fps": np.asarray(fps), **extra}


def run(spec, m, **params):
    return run_node(spec, params=params, motion=m)["motion"]


def amplitude(x, freq, fps=FPS):
    """Amplitude of the sinusoid of ``freq`` Hz in ``x`` (n,) (least squares on sin and cos)."""
    t = np.arange(x.shape[0]) / fps
    basis = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t), np.ones_like(t)], axis=1)
    coef = np.linalg.lstsq(basis, x, rcond=None)[0]
    return float(np.hypot(coef[0], coef[1]))


def test_butterworth_removes_high_frequency_keeps_low():
    t = np.arange(int(4 * FPS)) / FPS
    low = 0.10 * np.sin(2 * np.pi * 1.0 * t)
    high = 0.02 * np.sin(2 * np.pi * 30.0 * t)
    joints = np.zeros((t.size, 16, 3)) + (low + high)[:, None, None]
    joints += np.arange(16)[None, :, None] * 0.1  # different offsets per joint stay put
    tracked = np.ones((t.size, 16), dtype=bool)
    out = run(butterworth, motion(joints, tracked=tracked), cutoff=7.0, order=4)
    y = out["joints"][:, 5, 1] - 0.5
    inner = slice(60, -60)
    assert amplitude(y[inner], 30.0) < 0.02 * 0.01  # 30 Hz: under 1% left
    assert abs(amplitude(y[inner], 1.0) - 0.10) < 0.10 * 0.01  # 1 Hz: within 1%
    assert np.abs(out["joints"] - joints).mean() < 0.02  # no lag, no offset: close to the input
    assert np.array_equal(out["tracked"], tracked)


def test_butterworth_refuses_cutoff_above_nyquist_and_handles_short_clips():
    with pytest.raises(NodeError, match="Nyquist|half the frame rate"):
        run(butterworth, motion(np.zeros((50, 16, 3)), fps=10.0), cutoff=7.0)
    with pytest.raises(ValidationError):
        run(butterworth, motion(np.zeros((50, 16, 3))), cutoff=0.0)
    for n in (1, 2, 5):  # shorter than the filter's default padding
        out = run(butterworth, motion(np.ones((n, 16, 3))))
        assert np.allclose(out["joints"], 1.0)


def test_one_euro_reduces_jitter_on_a_still_joint():
    rng = np.random.default_rng(0)
    noisy = 0.3 + rng.normal(0, 0.005, size=(600, 16, 3))  # 5 mm jitter around a still pose
    out = run(one_euro, motion(noisy), min_cutoff=1.0, beta=1.0)["joints"]
    assert out[60:].std(axis=0).mean() < 0.25 * noisy[60:].std(axis=0).mean()
    assert abs(out[60:].mean() - 0.3) < 0.002


def test_one_euro_speed_term_reduces_lag_on_fast_motion():
    t = np.arange(240) / FPS
    ramp = np.zeros((t.size, 16, 3))
    ramp[:, :, 0] = 2.0 * t[:, None]  # 2 m/s
    lag_plain = np.abs(run(one_euro, motion(ramp), beta=0.0)["joints"] - ramp)[120:].mean()
    lag_adaptive = np.abs(run(one_euro, motion(ramp), beta=5.0)["joints"] - ramp)[120:].mean()
    assert lag_adaptive < 0.3 * lag_plain


def test_bone_length_makes_every_bone_constant():
    m = motion16_from_bvh(CLIP)
    rng = np.random.default_rng(1)
    noisy = m["joints"][:240] + rng.normal(0, 0.01, size=(240, 16, 3))
    out = run(bone_length, motion(noisy, joint_names=m["joint_names"]))
    lengths = sk.measure_bone_lengths(out["joints"])
    assert lengths[:, 1:].std(axis=0).max() < 1e-12
    assert np.allclose(lengths[0], np.median(sk.measure_bone_lengths(noisy), axis=0))
    assert np.array_equal(out["joints"][:, 0], noisy[:, 0])  # root unchanged
    # directions kept
    par = sk.PARENTS[1:]
    a = out["joints"][:, 1:] - out["joints"][:, par]
    b = noisy[:, 1:] - noisy[:, par]
    cos = np.sum(a * b, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
    assert cos.min() > 1 - 1e-12
    assert np.array_equal(out["joint_names"], m["joint_names"])


def test_bone_length_given_lengths_and_zero_length_bones():
    pose = np.repeat(sk.tpose()[None], 4, axis=0)
    pose[2, sk.JOINT_INDEX["left_wrist"]] = pose[2, sk.JOINT_INDEX["left_elbow"]]  # zero-length forearm
    out = run(bone_length, motion(pose), lengths={"left_wrist": 0.3})["joints"]
    assert np.isfinite(out).all()
    forearm = out[:, sk.JOINT_INDEX["left_wrist"]] - out[:, sk.JOINT_INDEX["left_elbow"]]
    assert np.allclose(forearm, [0.3, 0, 0])  # frame 2 takes frame 1's direction
    with pytest.raises(ValidationError, match="unknown bone"):
        run(bone_length, motion(pose), lengths={"left_wirst": 0.3})


def test_none_is_identity_and_filters_refuse_nan():
    joints = np.random.default_rng(2).normal(size=(10, 16, 3))
    out = run(none, motion(joints))
    assert np.array_equal(out["joints"], joints)
    joints[4, 7, 2] = np.inf
    for spec in (none, butterworth, one_euro, bone_length):
        with pytest.raises(NodeError, match="right_shoulder.*frame 4"):
            run(spec, motion(joints))
