"""The SMPL body model in numpy (Loper et al. 2015; seed 004), vectorised over frames.

Model arrays (an ``.npz`` the user supplies, made from the official file by
``python -m tbha_graph.mocap.smpl.convert``; the weights are licensed and are neither shipped nor downloaded).
``V`` vertices, ``B`` shape coefficients, 24 joints:

* ``v_template`` (V, 3) metres: mean template mesh T̄ in the rest T-pose (y up, facing +z);
* ``shapedirs`` (V, 3, B): shape blend shapes S (PCA directions);
* ``posedirs`` (V, 3, 207): pose blend shapes P over the 23 x 9 rotation-matrix features;
* ``J_regressor`` (24, V): joint regressor 𝒥 (dense);
* ``weights`` (V, 24): linear blend skinning weights (rows sum to 1);
* ``kintree_table`` (2, 24): row 0 the parent of each joint (the SMPL tree; root any negative or 2**32-1);
* ``f`` (F, 3) int: triangles (vertex indices).

Equations (:meth:`SmplModel.forward`), for shape β (B,), pose θ (n, 24, 3) axis-angle, translation (n, 3):

1. ``v_shaped = T̄ + S β``;  ``J = 𝒥 v_shaped`` (24, 3) rest joints;
2. ``R_k = exp(θ_k)`` (Rodrigues); ``v_posed = v_shaped + P · vec(R_1..23 − I)``;
3. ``G_k = G_parent(k) · [R_k | J_k − J_parent(k)]`` (``G_0 = [R_0 | J_0]``), world transforms;
4. skinning ``v = Σ_k w_k (G_k · [I | −J_k]) v_posed + trans`` and posed joints ``G_k[:, 3] + trans``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core.atomic import atomic_path
from ...core.errors import NodeError
from ...core.npzfile import read_npz
from .kintree import N_POSE_FEATURES, N_SMPL_JOINTS, SMPL_PARENTS

REQUIRED_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")

HOW_TO_GET_THE_MODEL = (
    "the SMPL model is licensed and not shipped: register at https://smpl.is.tue.mpg.de, download the "
    "SMPL model (e.g. basicmodel_neutral_lbs_10_207_0_v1.1.0.pkl), convert it once with "
    "`python -m tbha_graph.mocap.smpl.convert MODEL.pkl smpl_neutral.npz`, then set the node's model param "
    "to that .npz (e.g. --set mesh.model=smpl_neutral.npz)"
)


def expected_shapes(n_vertices: str | int = "V", n_betas: str | int = "B") -> dict[str, str]:
    """Human-readable expected shape of every model array."""
    return {
        "v_template": f"({n_vertices}, 3)", "shapedirs": f"({n_vertices}, 3, {n_betas})",
        "posedirs": f"({n_vertices}, 3, {N_POSE_FEATURES})", "J_regressor": f"({N_SMPL_JOINTS}, {n_vertices})",
        "weights": f"({n_vertices}, {N_SMPL_JOINTS})", "kintree_table": f"(2, {N_SMPL_JOINTS})", "f": "(F, 3)",
    }


def check_model_arrays(arrays: dict[str, np.ndarray], where: str = "SMPL model") -> dict[str, np.ndarray]:
    """Check keys, shapes and the kinematic tree of model arrays; return them as float64 / int64.

    Raises :class:`NodeError` listing every wrong or missing array with its expected shape.
    """
    missing = [k for k in REQUIRED_KEYS if k not in arrays]
    if missing:
        exp = expected_shapes()
        raise NodeError(f"{where}: missing array(s) {', '.join(missing)} (present: {', '.join(sorted(arrays)) or 'none'})",
                        hint="an SMPL model .npz holds " + ", ".join(f"{k} {exp[k]}" for k in REQUIRED_KEYS))
    a = {k: np.asarray(arrays[k]) for k in REQUIRED_KEYS}
    V = a["v_template"].shape[0] if a["v_template"].ndim == 2 else "V"
    B = a["shapedirs"].shape[2] if a["shapedirs"].ndim == 3 else "B"
    exp = expected_shapes(V, B)
    ok = {
        "v_template": a["v_template"].shape == (V, 3),
        "shapedirs": a["shapedirs"].ndim == 3 and a["shapedirs"].shape[:2] == (V, 3) and a["shapedirs"].shape[2] >= 1,
        "posedirs": a["posedirs"].shape == (V, 3, N_POSE_FEATURES),
        "J_regressor": a["J_regressor"].shape == (N_SMPL_JOINTS, V),
        "weights": a["weights"].shape == (V, N_SMPL_JOINTS),
        "kintree_table": a["kintree_table"].shape == (2, N_SMPL_JOINTS),
        "f": a["f"].ndim == 2 and a["f"].shape[1] == 3,
    }
    bad = [k for k, good in ok.items() if not good]
    if bad:
        raise NodeError(f"{where}: wrong array shape(s): " + "; ".join(f"{k} is {a[k].shape}, expected {exp[k]}" for k in bad),
                        hint="make the .npz with `python -m tbha_graph.mocap.smpl.convert` from the official SMPL file")
    out = {k: a[k].astype(np.float64) for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights")}
    for k, v in out.items():
        if not np.isfinite(v).all():
            raise NodeError(f"{where}: array {k} holds NaN or infinite values")
    parents = a["kintree_table"][0].astype(np.int64)
    parents[0] = -1
    parents = np.where(parents >= 2**31, -1, parents)
    if not np.array_equal(parents, SMPL_PARENTS):
        raise NodeError(f"{where}: kintree_table's parents {parents.tolist()} are not SMPL's {SMPL_PARENTS.tolist()}",
                        hint="only the 24-joint SMPL body model is supported (not SMPL-H / SMPL-X)")
    f = a["f"].astype(np.int64)
    if f.size and (f.min() < 0 or f.max() >= V):
        raise NodeError(f"{where}: f (triangles) indexes vertex {int(f.max())}, but there are {V} vertices")
    out["kintree_table"] = np.stack([parents, np.arange(N_SMPL_JOINTS)])
    out["f"] = f
    return out


def save_model_npz(arrays: dict[str, np.ndarray], path: str | Path) -> None:
    """Write checked model arrays to ``path`` (.npz) atomically (temp file in the same folder + rename)."""
    path = Path(path)
    checked = check_model_arrays(arrays, str(path))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **checked)


def rodrigues(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of axis-angle vectors ``(..., 3)`` (radians)."""
    from scipy.spatial.transform import Rotation

    rv = np.asarray(rotvec, dtype=np.float64)
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(rv.shape[:-1] + (3, 3))


@dataclass(frozen=True)
class SmplModel:
    """SMPL model arrays (see the module docstring for shapes and units)."""

    v_template: np.ndarray
    shapedirs: np.ndarray
    posedirs: np.ndarray
    J_regressor: np.ndarray
    weights: np.ndarray
    faces: np.ndarray

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], where: str = "SMPL model") -> "SmplModel":
        a = check_model_arrays(arrays, where)
        return cls(a["v_template"], a["shapedirs"], a["posedirs"], a["J_regressor"], a["weights"], a["f"])

    @property
    def n_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def n_betas(self) -> int:
        return int(self.shapedirs.shape[2])

    def _betas(self, betas) -> np.ndarray:
        b = np.zeros(self.n_betas) if betas is None else np.asarray(betas, dtype=np.float64).reshape(-1)
        if b.size > self.n_betas:
            if np.any(b[self.n_betas:]):
                raise NodeError(f"{b.size} shape coefficients given but the model has {self.n_betas}",
                                hint=f"give at most {self.n_betas} betas")
            b = b[: self.n_betas]
        return np.concatenate([b, np.zeros(self.n_betas - b.size)])

    def shaped(self, betas=None) -> np.ndarray:
        """Rest-pose mesh ``(V, 3)`` metres with shape blend shapes: ``T̄ + S β``."""
        return self.v_template + self.shapedirs @ self._betas(betas)

    def rest_joints(self, betas=None) -> np.ndarray:
        """Rest-pose joints ``(24, 3)`` metres: ``𝒥 (T̄ + S β)``."""
        return self.J_regressor @ self.shaped(betas)

    def forward(self, poses: np.ndarray, betas=None, trans: np.ndarray | None = None,
                chunk: int = 32) -> tuple[np.ndarray, np.ndarray]:
        """Posed vertices ``(n, V, 3)`` and joints ``(n, 24, 3)`` metres for ``poses`` ``(n, 72)`` (or
        ``(n, 24, 3)``) axis-angle radians, shape ``betas`` ``(B,)``, ``trans`` ``(n, 3)`` metres.
        Frames are processed ``chunk`` at a time (memory ~ chunk x V x 12 floats)."""
        theta = np.asarray(poses, dtype=np.float64).reshape(-1, N_SMPL_JOINTS, 3)
        n = theta.shape[0]
        tr = np.zeros((n, 3)) if trans is None else np.asarray(trans, dtype=np.float64).reshape(n, 3)
        v_shaped = self.shaped(betas)
        J = self.J_regressor @ v_shaped
        rel = J - J[np.maximum(SMPL_PARENTS, 0)]
        rel[0] = J[0]
        pose_dirs = self.posedirs.reshape(-1, N_POSE_FEATURES)  # (3V, 207)
        verts = np.empty((n, self.n_vertices, 3))
        joints = np.empty((n, N_SMPL_JOINTS, 3))
        eye = np.eye(3)
        for s in range(0, n, chunk):
            R = rodrigues(theta[s:s + chunk])  # (c, 24, 3, 3)
            c = R.shape[0]
            feat = (R[:, 1:] - eye).reshape(c, N_POSE_FEATURES)
            v_posed = v_shaped + (feat @ pose_dirs.T).reshape(c, -1, 3)
            G_R = np.empty((c, N_SMPL_JOINTS, 3, 3))
            G_t = np.empty((c, N_SMPL_JOINTS, 3))
            G_R[:, 0], G_t[:, 0] = R[:, 0], J[0]
            for k in range(1, N_SMPL_JOINTS):
                p = SMPL_PARENTS[k]
                G_R[:, k] = G_R[:, p] @ R[:, k]
                G_t[:, k] = G_t[:, p] + G_R[:, p] @ rel[k]
            joints[s:s + c] = G_t + tr[s:s + c, None]
            A_t = G_t - np.einsum("ckij,kj->cki", G_R, J)  # transform of the rest pose: G_k [I | -J_k]
            T_R = np.einsum("vk,ckij->cvij", self.weights, G_R)
            T_t = np.einsum("vk,cki->cvi", self.weights, A_t)
            verts[s:s + c] = np.einsum("cvij,cvj->cvi", T_R, v_posed) + T_t + tr[s:s + c, None]
        return verts, joints


def load_model(path: str | Path) -> SmplModel:
    """Load an SMPL model ``.npz`` (never a pickle); NodeError naming the file on any problem."""
    path = Path(path)
    if path.suffix.lower() == ".pkl":
        raise NodeError(f"{path} is a pickle: the pipeline loads only .npz model files",
                        hint=f"convert it once: python -m tbha_graph.mocap.smpl.convert {path} {path.with_suffix('.npz')}")
    if not path.is_file():
        raise NodeError(f"SMPL model file {path} does not exist", hint=HOW_TO_GET_THE_MODEL)
    arrays = read_npz(path, "SMPL model file", hint=HOW_TO_GET_THE_MODEL)  # no pickle, every member's CRC checked
    return SmplModel.from_arrays(arrays, str(path))
