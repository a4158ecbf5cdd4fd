"""filter.foot_contact on a real walk (CMU 131_02 at 30 fps) with noise added to the feet: contact
detection, foot locking by two-bone IK (sliding before/after), bone lengths, bend plane, modes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.kinematics import two_bone_ik
from tbha_graph.mocap.filter.foot_contact import (
    LEGS, FootContactParams, clean_contacts, detect_contacts, floor_height, foot_contact, runs,
)
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh
from tbha_graph.mocap.skeleton import JOINT_INDEX

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
FPS = 30.0
NOISE_M = 0.01  # per coordinate, on both ankles
LEG_JOINTS = sorted(j for leg in LEGS.values() for j in leg[1:])  # knees and ankles


@pytest.fixture(scope="module")
def walk() -> np.ndarray:
    return motion16_from_bvh(CLIP)["joints"][::4].copy()  # 120 -> 30 fps, 180 frames


@pytest.fixture(scope="module")
def noisy(walk) -> np.ndarray:
    j = walk.copy()
    ankles = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    j[:, ankles] += np.random.default_rng(0).normal(0.0, NOISE_M, size=(j.shape[0], 2, 3))
    return j


def run(joints, **params):
    out = run_node(foot_contact, params, motion={"joints": joints, "fps": np.asarray(FPS), "tracked": np.ones(joints.shape[:2], bool)})
    return out["motion"], out["report"]


def bone_lengths(j: np.ndarray) -> np.ndarray:
    return np.stack([np.linalg.norm(j[:, b] - j[:, a], axis=-1) for leg in LEGS.values() for a, b in zip(leg, leg[1:])], axis=1)


def test_locking_removes_foot_sliding_on_a_noisy_walk(noisy):
    out, rep = run(noisy)
    print(f"foot sliding {rep['foot_sliding_before_mm']:.2f} -> {rep['foot_sliding_after_mm']:.3f} mm per contact frame")
    assert rep["foot_sliding_before_mm"] > 10.0  # 1 cm noise: about 17 mm per frame
    assert rep["foot_sliding_after_mm"] < 0.5
    assert rep["foot_sliding_frame_pairs"] > 80
    for side in ("left", "right"):
        assert 0.2 < rep["contact_fraction"][side] < 0.6 and rep["contacts"][side] >= 3
    j = out["joints"]
    assert out["tracked"].all()  # other keys of the bundle are kept
    # bone lengths (hip-knee, knee-ankle) of every frame are those of the input
    assert np.abs(bone_lengths(j) - bone_lengths(noisy)).max() < 1e-9
    # only knees and ankles move; frames away from every contact are untouched
    others = [k for k in range(16) if k not in LEG_JOINTS]
    assert np.array_equal(j[:, others], noisy[:, others])
    moved = np.abs(j - noisy).max(axis=(1, 2)) > 0
    assert moved.mean() < 0.9 and moved.any()


def test_contacts_are_found_through_the_noise(walk, noisy):
    p = FootContactParams()
    clean = detect_contacts(walk, FPS, p, floor_height(walk, p.floor_percentile))
    found = detect_contacts(noisy, FPS, p, floor_height(noisy, p.floor_percentile))
    for side in LEGS:
        assert (clean[side] == found[side]).mean() > 0.9
        assert clean[side].sum() > 40
    # the ankle of a planted (clean) foot is slow and low; not so in swing
    a = walk[:, LEGS["left"][2]]
    speed = np.linalg.norm(np.gradient(a, axis=0), axis=-1) * FPS
    assert np.median(speed[clean["left"]]) < 0.15 < np.median(speed[~clean["left"]])


def test_knee_stays_in_its_bend_plane(noisy):
    out, _ = run(noisy)
    j = out["joints"]
    checked = 0
    for hip, knee, ankle in LEGS.values():
        changed = np.flatnonzero(np.abs(j[:, ankle] - noisy[:, ankle]).max(axis=1) > 1e-6)
        for f in changed:
            h, k0, k1, a1 = noisy[f, hip], noisy[f, knee], j[f, knee], j[f, ankle]
            u = (a1 - h) / np.linalg.norm(a1 - h)
            pole = (k0 - h) - np.dot(k0 - h, u) * u
            if np.linalg.norm(pole) < 0.03:  # nearly straight: bends forward instead
                continue
            normal = np.cross(u, pole / np.linalg.norm(pole))
            assert abs(np.dot(k1 - h, normal)) < 1e-9  # in the plane (hip, new ankle, original knee)
            assert np.dot(k1 - h, pole) > 0  # on the same side: the knee does not flip
            checked += 1
    assert checked > 20


def test_two_bone_ik_reaches_or_clamps_with_lengths_kept():
    rng = np.random.default_rng(1)
    m = 200
    hip = rng.normal(size=(m, 3))
    knee = hip + rng.normal(size=(m, 3)) * 0.3
    ankle = knee + rng.normal(size=(m, 3)) * 0.3
    target = hip + rng.normal(size=(m, 3)) * 0.4
    fwd = np.tile([0.0, 0.0, 1.0], (m, 1))
    k, a, clamped = two_bone_ik(hip, knee, ankle, target, fwd)
    l1, l2 = np.linalg.norm(knee - hip, axis=1), np.linalg.norm(ankle - knee, axis=1)
    assert np.allclose(np.linalg.norm(k - hip, axis=1), l1, atol=1e-9)
    assert np.allclose(np.linalg.norm(a - k, axis=1), l2, atol=1e-9)
    assert np.allclose(a[~clamped], target[~clamped], atol=1e-9) and (~clamped).sum() > 50
    d = np.linalg.norm(target - hip, axis=1)
    assert np.all((d[clamped] > l1[clamped] + l2[clamped] - 1e-6) | (d[clamped] < np.abs(l1 - l2)[clamped] + 1e-6))
    # a straight leg asked to bend bends forward
    k, a, _ = two_bone_ik(np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.5, 0.0]]), np.array([[0.0, 0.0, 0.0]]),
                          np.array([[0.0, 0.2, 0.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert k[0, 2] == pytest.approx(0.3) and np.allclose(a, [[0.0, 0.2, 0.0]])  # 0.4 down, 0.3 forward


def test_modes(walk, noisy):
    out, rep = run(noisy, mode="never")
    assert np.array_equal(out["joints"], noisy)
    assert rep["foot_sliding_after_mm"] == rep["foot_sliding_before_mm"] > 10.0
    # always: a standing take (one frame repeated, noisy ankles) gets both ankles pinned for the whole clip
    stand = np.repeat(walk[:1], 40, axis=0)
    stand[:, [12, 15]] += np.random.default_rng(2).normal(0.0, 0.005, size=(40, 2, 3))
    out, rep = run(stand, mode="always")
    for _, _, ankle in LEGS.values():
        assert np.ptp(out["joints"][:, ankle], axis=0).max() < 1e-9
    assert rep["contact_fraction"] == {"left": 1.0, "right": 1.0} and rep["foot_sliding_after_mm"] < 1e-6
    # grounding: the lower ankle sits at the floor height, only vertical moves
    lifted = noisy.copy()
    lifted[..., 1] += 0.02 * np.sin(np.arange(len(noisy)) / 10.0)[:, None]
    out, rep = run(lifted, mode="grounding")
    low = out["joints"][:, [12, 15], 1].min(axis=1)
    grounded = lifted[:, [12, 15], 1].min(axis=1) < rep["floor_ankle_height_m"] + 0.05
    assert np.allclose(low[grounded], rep["floor_ankle_height_m"], atol=1e-12) and grounded.mean() > 0.6
    assert np.array_equal(out["joints"][..., [0, 2]], lifted[..., [0, 2]])


def test_contact_cleaning_and_params():
    mask = np.array([0, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 0, 1, 1, 1, 1], dtype=bool)
    assert runs(mask) == [(1, 3), (4, 7), (10, 11), (12, 16)]
    clean = clean_contacts(mask, min_frames=3, max_gap=1)
    assert runs(clean_contacts(mask, min_frames=3, max_gap=0)) == [(4, 7), (12, 16)]
    assert runs(clean) == [(1, 7), (10, 16)]  # 1-frame gaps filled, then the 1-frame blip at 10 is part of a run
    with pytest.raises(ValidationError):
        FootContactParams(max_speed=0)
    with pytest.raises(ValidationError):
        FootContactParams(mode="sometimes")
