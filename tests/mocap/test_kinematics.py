"""Forward kinematics and quaternion helpers against scipy and hand-computed poses."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tbha_graph.mocap.kinematics import forward_kinematics, validate_parents
from tbha_graph.mocap.quat import quat_apply, quat_inv, quat_mul, quat_to_matrix


def _same_rotation(q1: np.ndarray, q2: np.ndarray, tol: float = 1e-12) -> bool:
    """q and -q are the same rotation."""
    d = np.minimum(np.abs(q1 - q2).max(axis=-1), np.abs(q1 + q2).max(axis=-1))
    return bool(d.max() < tol)


def test_quaternion_helpers_match_scipy() -> None:
    a = Rotation.random(200, random_state=1)
    b = Rotation.random(200, random_state=2)
    v = np.random.default_rng(3).normal(size=(200, 3))
    assert _same_rotation(quat_mul(a.as_quat(), b.as_quat()), (a * b).as_quat())
    assert np.allclose(quat_apply(a.as_quat(), v), a.apply(v), atol=1e-12)
    assert np.allclose(quat_to_matrix(a.as_quat()), a.as_matrix(), atol=1e-12)
    assert _same_rotation(quat_inv(a.as_quat()), a.inv().as_quat())
    # broadcasting: one quaternion against many vectors
    assert np.allclose(quat_apply(a.as_quat()[0], v), a[0].apply(v), atol=1e-12)


def test_fk_elbow_bent_90_degrees() -> None:
    """Shoulder at the origin, upper arm 0.3 m along +x, forearm 0.25 m; elbow flexed 90 deg about z."""
    parents = np.array([-1, 0, 1])
    offsets = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.25, 0.0, 0.0]])
    local = np.tile([0.0, 0.0, 0.0, 1.0], (2, 3, 1))
    local[:, 1] = Rotation.from_euler("z", 90, degrees=True).as_quat()
    root = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    pos, world = forward_kinematics(parents, offsets, local, root)
    assert np.allclose(pos[0], [[0, 0, 0], [0.3, 0, 0], [0.3, 0.25, 0]], atol=1e-12)
    assert np.allclose(pos[1] - root[1], pos[0], atol=1e-12)  # root translation moves everything
    assert _same_rotation(world[:, 2], local[:, 1])
    # turning the root 90 deg about y carries the bent arm with it: +x -> -z
    local[:, 0] = Rotation.from_euler("y", 90, degrees=True).as_quat()
    pos, _ = forward_kinematics(parents, offsets, local, np.zeros((2, 3)))
    assert np.allclose(pos[0], [[0, 0, 0], [0, 0, -0.3], [0, 0.25, -0.3]], atol=1e-12)


def test_fk_matches_matrix_chain_on_random_tree() -> None:
    rng = np.random.default_rng(0)
    parents = np.array([-1, 0, 1, 2, 0, 4, 1])
    offsets = rng.normal(size=(7, 3))
    n = 25
    rots = Rotation.random(n * 7, random_state=5)
    local = rots.as_quat().reshape(n, 7, 4)
    root = rng.normal(size=(n, 3))
    pos, world = forward_kinematics(parents, offsets, local, root)
    mats = rots.as_matrix().reshape(n, 7, 3, 3)
    wm = np.zeros_like(mats)
    ref = np.zeros((n, 7, 3))
    for j, p in enumerate(parents):
        if p < 0:
            wm[:, j], ref[:, j] = mats[:, j], root
        else:
            wm[:, j] = wm[:, p] @ mats[:, j]
            ref[:, j] = ref[:, p] + np.einsum("nij,j->ni", wm[:, p], offsets[j])
    assert np.allclose(pos, ref, atol=1e-12)
    assert np.allclose(quat_to_matrix(world), wm, atol=1e-12)
    # per-frame offsets (BVH joints with position channels) give the same result when constant
    pos2, _ = forward_kinematics(parents, np.broadcast_to(offsets, (n, 7, 3)), local, root)
    assert np.allclose(pos2, pos)


@pytest.mark.parametrize("parents", [[0, 0, 1], [-1, 2, 0], [-1, 0, -1], [-1, 1]])
def test_parents_must_precede_children(parents: list[int]) -> None:
    with pytest.raises(ValueError, match="joint"):
        validate_parents(np.array(parents))
    with pytest.raises(ValueError):
        forward_kinematics(np.array(parents), np.zeros((len(parents), 3)),
                           np.tile([0, 0, 0, 1.0], (1, len(parents), 1)), np.zeros((1, 3)))
