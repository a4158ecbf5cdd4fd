"""SMPL: the numpy model's equations on a small synthetic model file with the official layout, the restricted
pickle converter, the 16-joint -> SMPL pose conversion (checked by forward kinematics on CMU rotations), the
nodes and pipelines/smpl.yaml."""
from __future__ import annotations

import json
import pickle
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.skeleton import JOINT_INDEX, PARENTS
from tbha_graph.mocap.smpl.convert import main as convert_main, read_smpl_pickle
from tbha_graph.mocap.smpl.from_rotations import from_rotations
from tbha_graph.mocap.smpl.kintree import N_POSE_FEATURES, SMPL_INDEX, SMPL_PARENTS
from tbha_graph.mocap.smpl.mesh import mesh
from tbha_graph.mocap.smpl.model import SmplModel, check_model_arrays, load_model, rodrigues, save_model_npz
from tbha_graph.mocap.smpl.pose import Y_UP_TO_Z_UP, smpl_pose_from_rotations

ROOT = Path(__file__).resolve().parents[2]
CLIP = ROOT / "data" / "mocap" / "cmu" / "131_02.bvh"
N_EXTRA = 3  # skin vertices per joint


def default_rest_joints() -> np.ndarray:
    """A plausible SMPL-like T-pose (24, 3) metres, y up, facing +z, left = +x."""
    J = np.zeros((24, 3))
    pos = {
        "pelvis": (0, 0.9, 0), "left_hip": (0.09, 0.82, 0), "right_hip": (-0.09, 0.82, 0), "spine1": (0, 1.0, 0),
        "left_knee": (0.1, 0.45, 0), "right_knee": (-0.1, 0.45, 0), "spine2": (0, 1.13, 0), "left_ankle": (0.1, 0.07, 0),
        "right_ankle": (-0.1, 0.07, 0), "spine3": (0, 1.2, 0), "left_foot": (0.11, 0.02, 0.12),
        "right_foot": (-0.11, 0.02, 0.12), "neck": (0, 1.42, 0), "left_collar": (0.07, 1.35, 0),
        "right_collar": (-0.07, 1.35, 0), "head": (0, 1.5, 0.03), "left_shoulder": (0.18, 1.38, 0),
        "right_shoulder": (-0.18, 1.38, 0), "left_elbow": (0.44, 1.38, 0), "right_elbow": (-0.44, 1.38, 0),
        "left_wrist": (0.69, 1.38, 0), "right_wrist": (-0.69, 1.38, 0), "left_hand": (0.77, 1.38, 0),
        "right_hand": (-0.77, 1.38, 0),
    }
    for name, p in pos.items():
        J[SMPL_INDEX[name]] = p
    return J


def make_model(rest_joints: np.ndarray | None = None, seed: int = 0, weights: str = "random",
               pose_blend: bool = True) -> dict[str, np.ndarray]:
    """A small model with SMPL's array layout: 24 joint vertices (the regressor picks them) + skin vertices."""
    rng = np.random.default_rng(seed)
    J = default_rest_joints() if rest_joints is None else np.asarray(rest_joints, dtype=np.float64)
    skin = np.repeat(J, N_EXTRA, axis=0) + rng.normal(0, 0.03, (24 * N_EXTRA, 3))
    v = np.concatenate([J, skin])
    V = v.shape[0]
    reg = np.zeros((24, V))
    reg[np.arange(24), np.arange(24)] = 1.0
    owner = np.concatenate([np.arange(24), np.repeat(np.arange(24), N_EXTRA)])
    if weights == "onehot":
        w = np.zeros((V, 24))
        w[np.arange(V), owner] = 1.0
    else:
        # like SMPL: a few influences per vertex (its own joint and one other)
        w = np.zeros((V, 24))
        w[np.arange(V), owner] = rng.uniform(0.5, 1.0, V)
        w[np.arange(V), rng.integers(0, 24, V)] += rng.uniform(0.0, 0.5, V)
        w /= w.sum(axis=1, keepdims=True)
    kintree = np.stack([np.where(SMPL_PARENTS < 0, 2**32 - 1, SMPL_PARENTS), np.arange(24)]).astype(np.uint32)
    return {
        "v_template": v, "shapedirs": rng.normal(0, 0.01, (V, 3, 10)),
        "posedirs": rng.normal(0, 0.01, (V, 3, N_POSE_FEATURES)) if pose_blend else np.zeros((V, 3, N_POSE_FEATURES)),
        "J_regressor": reg, "weights": w, "kintree_table": kintree, "f": rng.integers(0, V, (40, 3)),
    }


def random_poses(n: int, seed: int = 1, scale: float = 0.4) -> np.ndarray:
    return np.random.default_rng(seed).normal(0, scale, (n, 72))


# --- the model's equations ------------------------------------------------------------------------------
def test_rest_pose_returns_the_template():
    arrays = make_model()
    m = SmplModel.from_arrays(arrays)
    verts, joints = m.forward(np.zeros((2, 72)))
    assert np.allclose(verts, arrays["v_template"], atol=1e-12)
    assert np.allclose(joints, arrays["J_regressor"] @ arrays["v_template"], atol=1e-12)
    trans = np.array([[1.0, 2.0, 3.0], [0.0, -1.0, 0.5]])
    verts_t, _ = m.forward(np.zeros((2, 72)), trans=trans)
    assert np.allclose(verts_t - verts, trans[:, None], atol=1e-12)


def test_shape_blend_is_linear_in_beta():
    m = SmplModel.from_arrays(make_model())
    b1, b2 = np.random.default_rng(3).normal(0, 1, (2, 10))
    d = lambda b: m.shaped(b) - m.shaped(None)  # noqa: E731
    assert np.allclose(d(b1 + b2), d(b1) + d(b2), atol=1e-12)
    assert np.allclose(d(2.5 * b1), 2.5 * d(b1), atol=1e-12)
    verts, _ = m.forward(np.zeros((1, 72)), betas=b1)
    assert np.allclose(verts[0], m.v_template + m.shapedirs @ b1, atol=1e-12)


def test_pose_blend_is_zero_at_rest_and_follows_the_rotation_features():
    with_pb = SmplModel.from_arrays(make_model(weights="onehot"))
    without = SmplModel.from_arrays(make_model(weights="onehot", pose_blend=False))
    poses = random_poses(3)
    poses[:, :3] = 0.0  # no global rotation: vertices owned by the pelvis are not moved by skinning
    va, _ = with_pb.forward(poses)
    vb, _ = without.forward(poses)
    R = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(3, 24, 3, 3)
    feat = (R[:, 1:] - np.eye(3)).reshape(3, N_POSE_FEATURES)
    expected = np.einsum("vcp,fp->fvc", with_pb.posedirs, feat)
    pelvis_owned = np.flatnonzero(with_pb.weights[:, 0] == 1.0)
    assert np.allclose((va - vb)[:, pelvis_owned], expected[:, pelvis_owned], atol=1e-12)
    assert np.abs(expected[:, pelvis_owned]).max() > 1e-4  # the check is not vacuous
    v0, _ = with_pb.forward(np.zeros((1, 72)))
    assert np.allclose(v0[0], with_pb.v_template, atol=1e-12)


def test_a_joint_rotation_moves_only_vertices_weighted_to_it_or_its_descendants():
    m = SmplModel.from_arrays(make_model(pose_blend=False))
    k = SMPL_INDEX["left_elbow"]
    poses = np.zeros((1, 72))
    poses[0, 3 * k: 3 * k + 3] = [0.0, 0.0, 0.9]
    verts, joints = m.forward(poses)
    moved = np.linalg.norm(verts[0] - m.v_template, axis=1) > 1e-12
    subtree = [k, SMPL_INDEX["left_wrist"], SMPL_INDEX["left_hand"]]
    weighted = m.weights[:, subtree].sum(axis=1) > 0
    skin = slice(24, None)  # the first 24 vertices sit on the joints; the elbow's own one is the pivot
    assert np.array_equal(moved[skin], weighted[skin])
    assert 0 < moved.sum() < len(moved) // 2
    assert not moved[k] and moved[SMPL_INDEX["left_wrist"]]
    assert np.allclose(joints[0, : k + 1], m.rest_joints()[: k + 1])  # the elbow itself and earlier joints stay


def test_skinning_matches_a_per_vertex_reference():
    """Linear blend skinning against an independent loop over joints with 4x4 matrices."""
    arrays = make_model(seed=5)
    m = SmplModel.from_arrays(arrays)
    pose, beta, trans = random_poses(1, seed=7)[0], np.random.default_rng(8).normal(0, 1, 10), np.array([0.3, -0.2, 1.0])
    verts, joints = m.forward(pose[None], beta, trans[None])
    vs = m.v_template + np.einsum("vcb,b->vc", m.shapedirs, beta)
    J = m.J_regressor @ vs
    R = [Rotation.from_rotvec(pose[3 * i: 3 * i + 3]).as_matrix() for i in range(24)]
    vp = vs + m.posedirs.reshape(-1, N_POSE_FEATURES).dot(np.concatenate([(r - np.eye(3)).ravel() for r in R[1:]])).reshape(-1, 3)
    G = []
    for i in range(24):
        local = np.eye(4)
        local[:3, :3] = R[i]
        local[:3, 3] = J[i] - (J[SMPL_PARENTS[i]] if i else 0.0)
        G.append(local if i == 0 else G[SMPL_PARENTS[i]] @ local)
    ref = np.zeros_like(vp)
    for i in range(24):
        A = G[i].copy()
        A[:3, 3] -= G[i][:3, :3] @ J[i]
        ref += m.weights[:, i:i + 1] * (vp @ A[:3, :3].T + A[:3, 3])
    assert np.allclose(verts[0], ref + trans, atol=1e-10)
    assert np.allclose(joints[0], np.array([g[:3, 3] for g in G]) + trans, atol=1e-10)


def test_rodrigues_matches_the_textbook_formula():
    w = np.array([0.3, -0.5, 0.8])
    th = np.linalg.norm(w)
    k = w / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    assert np.allclose(rodrigues(w), np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K)


# --- model files ----------------------------------------------------------------------------------------
def test_wrong_shapes_are_refused_with_the_expected_shapes(tmp_path):
    arrays = make_model()
    bad = dict(arrays, posedirs=arrays["posedirs"][..., :200])
    with pytest.raises(NodeError, match=r"posedirs is \(96, 3, 200\), expected \(96, 3, 207\)"):
        check_model_arrays(bad)
    bad = dict(arrays, J_regressor=arrays["J_regressor"][:, :-1], weights=arrays["weights"][:, :23])
    with pytest.raises(NodeError, match=r"J_regressor is \(24, 95\), expected \(24, 96\).*weights is \(96, 23\), expected \(96, 24\)"):
        check_model_arrays(bad)
    with pytest.raises(NodeError, match=r"missing array\(s\) f"):
        check_model_arrays({k: v for k, v in arrays.items() if k != "f"})
    kt = arrays["kintree_table"].copy()
    kt[0, 5] = 1
    with pytest.raises(NodeError, match="not SMPL's"):
        check_model_arrays(dict(arrays, kintree_table=kt))
    path = tmp_path / "m.npz"
    np.savez(path, **bad)
    with pytest.raises(NodeError, match=str(path)):
        load_model(path)


def test_model_npz_round_trip_and_pickles_are_not_loaded(tmp_path):
    arrays = make_model()
    path = tmp_path / "model.npz"
    save_model_npz(arrays, path)
    m = load_model(path)
    assert np.allclose(m.v_template, arrays["v_template"])
    with pytest.raises(NodeError, match="convert it once"):
        load_model(tmp_path / "model.pkl")
    with pytest.raises(NodeError, match="smpl.is.tue.mpg.de"):
        load_model(tmp_path / "absent.npz")


@pytest.fixture
def fake_chumpy(monkeypatch):
    """A stand-in for chumpy.ch.Ch (pickled with the same module/class name and __dict__ state)."""
    chumpy = types.ModuleType("chumpy")
    ch = types.ModuleType("chumpy.ch")

    class Ch:
        def __init__(self, x):
            self.x = np.asarray(x)
            self._dirty_vars = set()

    Ch.__module__ = "chumpy.ch"
    Ch.__qualname__ = "Ch"
    ch.Ch = Ch
    chumpy.ch = ch
    monkeypatch.setitem(sys.modules, "chumpy", chumpy)
    monkeypatch.setitem(sys.modules, "chumpy.ch", ch)
    return Ch


@pytest.mark.parametrize("protocol", [0, 2])
def test_converter_reads_the_official_layout(tmp_path, fake_chumpy, protocol):
    from scipy.sparse import csc_matrix

    arrays = make_model()
    official = {
        "v_template": arrays["v_template"], "shapedirs": fake_chumpy(arrays["shapedirs"]),
        "posedirs": arrays["posedirs"], "J_regressor": csc_matrix(arrays["J_regressor"]),
        "weights": arrays["weights"], "kintree_table": arrays["kintree_table"].astype(np.int64),
        "f": arrays["f"].astype(np.uint32), "bs_style": "lbs", "bs_type": "lrotmin",
        "J": arrays["J_regressor"] @ arrays["v_template"], "vert_sym_idxs": np.arange(5),
    }
    src = tmp_path / "model.pkl"
    src.write_bytes(pickle.dumps(official, protocol=protocol))
    dst = tmp_path / "model.npz"
    assert convert_main([str(src), str(dst)]) == 0
    m = load_model(dst)
    assert np.allclose(m.shapedirs, arrays["shapedirs"])
    assert np.allclose(m.J_regressor, arrays["J_regressor"])
    assert np.array_equal(m.faces, arrays["f"])


def test_converter_refuses_other_classes(tmp_path):
    target = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (Path.touch, (target,))

    src = tmp_path / "evil.pkl"
    src.write_bytes(pickle.dumps({"v_template": Evil()}, protocol=2))
    with pytest.raises(NodeError, match=r"evil\.pkl: refused to load builtins\.getattr"):
        read_smpl_pickle(src)
    assert not target.exists()
    assert convert_main([str(src), str(tmp_path / "out.npz")]) == 1
    assert not (tmp_path / "out.npz").exists()


# --- 16-joint rotations -> SMPL -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cmu_rotations():
    rot = rotations16_from_bvh(CLIP)
    keep = slice(0, 720, 12)
    return {k: (v[keep] if k in ("local_quat", "root_position") else v) for k, v in rot.items()}


def rest_joints_of(rot) -> np.ndarray:
    """SMPL rest joints placed on the 16-joint skeleton's own rest pose (collars at the chest, spine on the
    hips->chest line, hands/feet at the End Sites)."""
    n16 = np.tile([0.0, 0.0, 0.0, 1.0], (1, 16, 1))
    rest, _ = forward_kinematics(PARENTS, rot["offsets"], n16, np.zeros((1, 3)))
    P = {n: rest[0, i] for n, i in JOINT_INDEX.items()}
    J = np.zeros((24, 3))
    same = {"pelvis": "hips", "spine3": "chest", "neck": "neck", "head": "head", "left_collar": "chest",
            "right_collar": "chest"}
    for s in ("left", "right"):
        for a in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
            same[f"{s}_{a}"] = f"{s}_{a}"
        J[SMPL_INDEX[f"{s}_hand"]] = P[f"{s}_wrist"] + rot["end_offsets"][JOINT_INDEX[f"{s}_wrist"]]
        J[SMPL_INDEX[f"{s}_foot"]] = P[f"{s}_ankle"] + rot["end_offsets"][JOINT_INDEX[f"{s}_ankle"]]
    for smpl_name, ours in same.items():
        J[SMPL_INDEX[smpl_name]] = P[ours]
    J[SMPL_INDEX["spine1"]] = P["hips"] + (P["chest"] - P["hips"]) / 3
    J[SMPL_INDEX["spine2"]] = P["hips"] + 2 * (P["chest"] - P["hips"]) / 3
    return J


def test_smpl_pose_reproduces_the_16_joint_motion(cmu_rotations):
    """An SMPL skeleton built on the same rest pose, posed by the converted parameters, puts every joint the
    16-joint model has exactly where forward kinematics of the rotations puts it (real CMU motion)."""
    rot = cmu_rotations
    J = rest_joints_of(rot)
    model = SmplModel.from_arrays(make_model(J, pose_blend=False))
    poses, trans = smpl_pose_from_rotations(rot["local_quat"], rot["root_position"], rest_joints=J, spine="top")
    _, smpl_joints = model.forward(poses, trans=trans)
    fk, _ = forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])
    pairs = {"pelvis": "hips", "spine3": "chest", "neck": "neck", "head": "head"}
    pairs.update({f"{s}_{a}": f"{s}_{a}" for s in ("left", "right") for a in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")})
    for smpl_name, ours in pairs.items():
        err = np.abs(smpl_joints[:, SMPL_INDEX[smpl_name]] - fk[:, JOINT_INDEX[ours]]).max()
        assert err < 1e-9, (smpl_name, err)
    assert np.ptp(fk[:, JOINT_INDEX["left_wrist"]], axis=0).max() > 0.2  # the clip really moves


def test_even_spine_split_composes_to_the_chest_rotation(cmu_rotations):
    rot = cmu_rotations
    poses, _ = smpl_pose_from_rotations(rot["local_quat"], rot["root_position"], spine="even")
    p = poses.reshape(-1, 24, 3)
    s1, s2, s3 = (p[:, SMPL_INDEX[n]] for n in ("spine1", "spine2", "spine3"))
    assert np.allclose(s1, s2) and np.allclose(s2, s3)
    total = Rotation.from_rotvec(s1) * Rotation.from_rotvec(s2) * Rotation.from_rotvec(s3)
    chest = Rotation.from_quat(rot["local_quat"][:, JOINT_INDEX["chest"]])
    assert np.allclose((total.inv() * chest).magnitude(), 0.0, atol=1e-9)
    for unseen in ("left_collar", "right_collar", "left_hand", "right_hand", "left_foot", "right_foot"):
        assert np.all(p[:, SMPL_INDEX[unseen]] == 0.0)


def test_rest_limb_directions_are_aligned_when_the_model_is_known():
    J = default_rest_joints()
    # SMPL-like template arms slope 10 degrees down from the shoulder
    for s, sign in (("left", 1.0), ("right", -1.0)):
        sh = J[SMPL_INDEX[f"{s}_shoulder"]]
        for part, dist in (("elbow", 0.26), ("wrist", 0.51), ("hand", 0.59)):
            J[SMPL_INDEX[f"{s}_{part}"]] = sh + dist * np.array([sign * np.cos(np.radians(10)), -np.sin(np.radians(10)), 0.0])
    model = SmplModel.from_arrays(make_model(J, pose_blend=False))
    identity = np.tile([0.0, 0.0, 0.0, 1.0], (1, 16, 1))
    for rest, want_level in ((J, True), (None, False)):
        poses, trans = smpl_pose_from_rotations(identity, np.zeros((1, 3)), rest_joints=rest)
        _, j = model.forward(poses, trans=trans)
        arm = j[0, SMPL_INDEX["left_wrist"]] - j[0, SMPL_INDEX["left_shoulder"]]
        level = abs(arm[1]) / np.linalg.norm(arm) < 1e-9
        assert level == want_level


def test_z_up_output_turns_the_body_and_keeps_the_pelvis_on_the_root(cmu_rotations):
    rot = cmu_rotations
    J = rest_joints_of(rot)
    model = SmplModel.from_arrays(make_model(J, pose_blend=False))
    poses, trans = smpl_pose_from_rotations(rot["local_quat"], rot["root_position"], rest_joints=J, up="z")
    _, j = model.forward(poses, trans=trans)
    assert np.allclose(j[:, 0], rot["root_position"] @ Y_UP_TO_Z_UP.T, atol=1e-9)
    assert (j[:, SMPL_INDEX["head"], 2] > j[:, 0, 2] + 0.3).all()


# --- nodes and pipeline ----------------------------------------------------------------------------------
def test_from_rotations_node_writes_amass_keys(cmu_rotations, tmp_path):
    out = run_node(from_rotations, {"betas": [0.5] + [0.0] * 9, "gender": "female"}, rotations=cmu_rotations)["params"]
    n = cmu_rotations["local_quat"].shape[0]
    assert out["poses"].shape == (n, 72) and out["trans"].shape == (n, 3) and out["betas"].shape == (10,)
    assert str(out["gender"]) == "female" and float(out["mocap_framerate"]) == pytest.approx(120.0, abs=1e-3)
    with pytest.raises(ValidationError, match="gender"):
        run_node(from_rotations, {"gender": "other"}, rotations=cmu_rotations)
    model_path = tmp_path / "m.npz"
    save_model_npz(make_model(rest_joints_of(cmu_rotations)), model_path)
    with_model = run_node(from_rotations, {"model": model_path}, rotations=cmu_rotations)["params"]
    # the model's pelvis (rest joint 0 at the origin here) leaves trans on the root
    assert np.allclose(with_model["trans"], cmu_rotations["root_position"], atol=1e-9)


def test_mesh_node_explains_the_model_and_writes_obj(cmu_rotations, tmp_path):
    params = run_node(from_rotations, rotations=cmu_rotations)["params"]
    with pytest.raises(NodeError, match=r"no SMPL model file configured") as e:
        run_node(mesh, {}, smpl=params)
    assert "smpl.is.tue.mpg.de" in str(e.value) and "tbha_graph.mocap.smpl.convert" in str(e.value)
    arrays = make_model(rest_joints_of(cmu_rotations))
    model_path = tmp_path / "m.npz"
    save_model_npz(arrays, model_path)
    out = run_node(mesh, {"model": model_path, "start": 2, "stop": 20, "step": 8}, smpl=params)["mesh"]
    text = Path(out).read_text().splitlines()
    objects = [line for line in text if line.startswith("o ")]
    assert objects == ["o frame_000002", "o frame_000010", "o frame_000018"]
    V = arrays["v_template"].shape[0]
    verts = np.array([[float(x) for x in line.split()[1:]] for line in text if line.startswith("v ")])
    faces = np.array([[int(x) for x in line.split()[1:]] for line in text if line.startswith("f ")])
    assert verts.shape == (3 * V, 3) and faces.min() >= 1 and faces.max() <= 3 * V
    want, _ = SmplModel.from_arrays(arrays).forward(params["poses"][[2, 10, 18]], params["betas"], params["trans"][[2, 10, 18]])
    assert np.abs(verts - want.reshape(-1, 3)).max() < 2e-6
    assert np.array_equal(faces[len(arrays["f"]): 2 * len(arrays["f"])] - 1 - V, arrays["f"])
    with pytest.raises(NodeError, match="max_frames"):
        run_node(mesh, {"model": model_path, "step": 1, "max_frames": 5}, smpl=params)


def test_smpl_pipeline_runs(tmp_path):
    from tbha_graph.core.cache import Cache
    from tbha_graph.core.runner import load_graph, run_graph

    run_graph(load_graph(ROOT / "pipelines" / "smpl.yaml"), out_dir=tmp_path / "run", cache=Cache(tmp_path / "cache"))
    with np.load(tmp_path / "run" / "smpl.npz", allow_pickle=False) as z:
        assert z["poses"].shape[1] == 72 and z["poses"].shape[0] == z["trans"].shape[0] > 100
        assert str(z["gender"]) == "neutral"
        assert np.isfinite(z["poses"]).all()
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())
