"""``reconstruct.sequence_lsq``: 3D joints by least squares over windows of frames.

Unknowns, per joint and frame of a window: normalised image coordinates ``(x, y)`` and depth ``Z`` (metres,
camera frame; ``P = Z·(x, y, 1)``). Residuals, each divided by its standard deviation so they are unit-free:

* reprojection: ``f·(x − x̂)``, ``f·(y − ŷ)`` pixels against the (undistorted) 2D tracks, σ = ``sigma_px``;
  joints not tracked in a frame (``tracked`` False, ``points`` a prediction) count ``untracked_weight`` times less;
* bone lengths: ``|P_j − P_parent| − L_j`` metres, σ = ``sigma_bone``; the shoulder triangle's third side
  (shoulder to shoulder, measured on the first frame by ray_sphere) too;
* smoothness: second differences over frames of ``(x, y)`` and of ``Z``, σ = ``sigma_accel``·dt² (an
  acceleration in m/s², so the same value suits any frame rate; ``(x, y)`` use it divided by the window's
  median depth). Penalising camera-frame positions instead would favour moving the body towards the
  camera, where the same image motion is a smaller 3D motion.

Solved with ``scipy.optimize.least_squares`` (``trf``, LSMR subproblems) and an analytic sparse Jacobian
(each residual touches at most 6 unknowns). Start: ``reconstruct.ray_sphere``'s solution (same first-frame
rule, ``continuity`` param), computed on the raw 2D and on 2D smoothed over time (``init_smoothing``); each
window is solved from every start and the lowest final cost wins. Windows of ``window`` frames overlap by
``overlap`` frames (the next window starts from the previous one's solution there) and are cross-faded.

Limits (measured, see the report to the lead): single-view depth with only bone lengths has no redundancy
per frame, so the smoothness prior does the work; with 1 px noise expect decimetre MPJPE, not centimetres.
The LSMR inner loop is made of many small BLAS calls: run with ``OPENBLAS_NUM_THREADS=1`` on a busy machine
(about 7x faster here).
"""
from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.node import node
from ..bundles.tracks import read_tracks
from ..camera import Camera
from ..ports import BODY, CAMERA, MOTION, TRACKS2D, report_port
from ..skeleton import BONES, JOINT_INDEX, N_JOINTS
from ..body import body_lengths
from .ray_sphere import check_image_size, motion_bundle, ray_directions, solve_ray_sphere

_LS, _RS = JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]
#: Pairs with a fixed distance: the 15 bones and the shoulder-to-shoulder side of the triangle.
PAIRS = np.concatenate([BONES, [[_LS, _RS]]])


class SequenceLsqParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    window: int = Field(120, ge=3, le=5000, description="frames solved together")
    overlap: int = Field(20, ge=0, description="frames shared by consecutive windows (cross-faded)")
    sigma_px: float = Field(1.0, gt=0, description="2D tracking noise", json_schema_extra={"unit": "px"})
    sigma_bone: float = Field(0.005, gt=0, description="allowed bone-length deviation", json_schema_extra={"unit": "m"})
    sigma_accel: float = Field(40.0, gt=0, description="typical joint acceleration (smoothness)", json_schema_extra={"unit": "m/s^2"})
    untracked_weight: float = Field(0.1, ge=0, le=1, description="weight of a 2D prediction where the joint is not tracked")
    loss: Literal["linear", "soft_l1", "huber", "cauchy"] = Field("linear", description="robust loss on all residuals (scipy.optimize.least_squares)")
    max_nfev: int = Field(30, ge=1, description="most solver iterations per window")
    lsmr_iterations: int = Field(50, ge=5, description="most inner LSMR iterations per solver step (trust-region subproblem)")
    continuity: Literal["previous", "velocity"] = Field("velocity", description="two-root rule of the ray_sphere initialisation")
    init_smoothing: list[Annotated[float, Field(ge=0)]] = Field(
        [0.0, 0.05], min_length=1,
        description="ray_sphere initialisations tried, each on the 2D tracks smoothed over time by this Gaussian sigma "
        "(0: raw); per window the one reaching the lowest cost wins", json_schema_extra={"unit": "s"},
    )
    plane_z: float | None = Field(None, description="as ray_sphere: world z of the coronal plane on the first frame", json_schema_extra={"unit": "m"})

    @model_validator(mode="after")
    def _overlap_smaller(self) -> "SequenceLsqParams":
        if self.overlap >= self.window:
            raise ValueError(f"overlap ({self.overlap}) must be smaller than window ({self.window})")
        return self


class WindowProblem:
    """Residuals and sparse Jacobian of one window (see module doc).

    Unknowns per joint and frame: normalised image coordinates ``(x, y)`` (``P = Z·(x, y, 1)``) and depth ``Z``
    metres, flattened as ``x`` of shape ``(m * N_JOINTS * 3,)``. In these coordinates the reprojection is
    linear, and smoothness is measured on ``(x, y)`` and on ``Z`` separately: a smoothness term on camera-frame
    positions would favour moving the whole body towards the camera (where the same image motion is a
    smaller 3D motion), biasing depth.
    """

    def __init__(self, obs: np.ndarray, weights: np.ndarray, focal: float, dists: np.ndarray,
                 sigma_px: float, sigma_bone: float, sigma_step_m: float, depth: float):
        from scipy.sparse import coo_matrix

        self.obs = obs  # (m, 16, 2) normalised image coordinates of the 2D tracks
        self.m = obs.shape[0]
        self.w = np.repeat(weights[..., None], 2, axis=-1) * (focal / sigma_px)  # (m, 16, 2)
        self.dists = dists  # (n_pairs,)
        self.sb = sigma_bone
        self.s_xy = sigma_step_m / depth  # normalised units per frame^2
        self.s_z = sigma_step_m
        m, J = self.m, N_JOINTS
        idx = np.arange(m * J * 3).reshape(m, J, 3)
        n_rep = m * J * 2
        n_pair = m * len(PAIRS)
        n_acc = max(m - 2, 0) * J * 3
        self.n_res, self.n_var = n_rep + n_pair + n_acc, m * J * 3
        # fixed sparsity pattern (row, col); values are filled in jac()
        rows = [np.arange(n_rep)]
        cols = [idx[..., :2].ravel()]
        r_pair = n_rep + np.arange(n_pair).reshape(m, len(PAIRS))
        rows.append(np.repeat(r_pair[..., None], 6, axis=2).ravel())
        cols.append(np.concatenate([idx[:, PAIRS[:, 1]], idx[:, PAIRS[:, 0]]], axis=2).ravel())
        acc_vals = np.zeros(0)
        if n_acc:
            r_acc = n_rep + n_pair + np.arange(n_acc).reshape(m - 2, J, 3)
            rows.append(np.repeat(r_acc[..., None], 3, axis=3).ravel())
            cols.append(np.stack([idx[:-2], idx[1:-1], idx[2:]], axis=3).ravel())
            scale = np.array([1.0 / self.s_xy, 1.0 / self.s_xy, 1.0 / self.s_z])
            acc_vals = (np.array([1.0, -2.0, 1.0])[None, None, None, :] * scale[None, None, :, None] * np.ones((m - 2, J, 3, 3))).ravel()
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self._rep_vals = self.w.ravel()
        self._acc_vals = acc_vals
        self._acc_scale = np.array([1.0 / self.s_xy, 1.0 / self.s_xy, 1.0 / self.s_z])
        self._coo = coo_matrix

    @staticmethod
    def to_params(P: np.ndarray) -> np.ndarray:
        """Camera-frame positions ``(m, 16, 3)`` -> unknowns ``(m * 16 * 3,)``."""
        Z = np.maximum(P[..., 2], 1e-3)
        return np.concatenate([P[..., :2] / Z[..., None], Z[..., None]], axis=-1).ravel()

    def to_points(self, x: np.ndarray) -> np.ndarray:
        """Unknowns -> camera-frame positions ``(m, 16, 3)`` metres."""
        q = x.reshape(self.m, N_JOINTS, 3)
        return np.concatenate([q[..., :2] * q[..., 2:3], q[..., 2:3]], axis=-1)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        q = x.reshape(self.m, N_JOINTS, 3)
        rep = ((q[..., :2] - self.obs) * self.w).ravel()
        P = self.to_points(x)
        e = P[:, PAIRS[:, 1]] - P[:, PAIRS[:, 0]]
        pair = ((np.linalg.norm(e, axis=-1) - self.dists) / self.sb).ravel()
        acc = ((q[2:] - 2.0 * q[1:-1] + q[:-2]) * self._acc_scale).ravel()
        return np.concatenate([rep, pair, acc])

    def jac(self, x: np.ndarray):
        q = x.reshape(self.m, N_JOINTS, 3)
        P = self.to_points(x)
        e = P[:, PAIRS[:, 1]] - P[:, PAIRS[:, 0]]
        u = e / (np.linalg.norm(e, axis=-1, keepdims=True) * self.sb)  # d r / d P_child
        # dP/d(x, y, Z) = [[Z, 0, x], [0, Z, y], [0, 0, 1]]
        def chain(j):
            qj = q[:, PAIRS[:, j]]
            Z = qj[..., 2:3]
            return np.concatenate([u[..., :2] * Z, (u[..., :1] * qj[..., :1] + u[..., 1:2] * qj[..., 1:2] + u[..., 2:3])], axis=-1)
        vp = np.concatenate([chain(1), -chain(0)], axis=2)
        vals = np.concatenate([self._rep_vals, vp.ravel(), self._acc_vals])
        return self._coo((vals, (self.rows, self.cols)), shape=(self.n_res, self.n_var)).tocsr()


def initial_solutions(pixels: np.ndarray, cam: Camera, lengths: np.ndarray, dt: float, p: SequenceLsqParams) -> tuple[list[np.ndarray], float, int]:
    """ray_sphere solutions ``(n, 16, 3)`` camera frame, one per ``p.init_smoothing`` value (Gaussian over time on the
    2D, seconds; 0 = raw); also the shoulder-to-shoulder side (m) and the no-root count of the raw one."""
    from scipy.ndimage import gaussian_filter1d

    inits, side, no_root = [], None, 0
    for sigma in p.init_smoothing:
        px = gaussian_filter1d(pixels, sigma / dt, axis=0, mode="nearest") if sigma > 0 and len(pixels) > 1 else pixels
        P, stats = solve_ray_sphere(px, cam, lengths, p.plane_z, p.continuity)
        inits.append(P)
        if side is None or sigma == 0:
            side, no_root = stats.triangle_sides_m[2], int(sum(stats.no_root.values()))
    return inits, float(side), no_root


def solve_sequence_lsq(pixels: np.ndarray, tracked: np.ndarray, cam: Camera, lengths: np.ndarray, fps: float,
                       p: SequenceLsqParams, init: np.ndarray | None = None, progress=None) -> tuple[np.ndarray, dict]:
    """Joint positions ``(n, N_JOINTS, 3)`` metres **camera frame** by windowed least squares (module doc).

    ``init`` (n, 16, 3) camera frame: the starting solution; else ray_sphere's (one candidate per
    ``init_smoothing`` value; per window the candidate reaching the lowest cost wins). Returns the positions and
    a report dict (initial/final reprojection RMS px, bone-length RMS mm, windows, solver evaluations).
    """
    from scipy.optimize import least_squares

    pixels = np.asarray(pixels, dtype=np.float64)
    n = pixels.shape[0]
    dt = 1.0 / fps if fps > 0 else 1.0 / 30.0
    report: dict = {}
    if init is None:
        inits, side, report["init_no_root_total"] = initial_solutions(pixels, cam, lengths, dt, p)
    else:
        inits, side = [np.asarray(init, dtype=np.float64)], float(np.linalg.norm(init[0, _LS] - init[0, _RS]))
    dists = np.concatenate([lengths[BONES[:, 1]], [side]])
    rays = ray_directions(cam, pixels)
    weights = np.where(tracked, 1.0, p.untracked_weight)
    sigma_step = p.sigma_accel * dt * dt
    out = np.zeros((n, N_JOINTS, 3))
    wsum = np.zeros(n)
    step = p.window - p.overlap
    starts = [0] + [s for s in range(step, n, step) if s + p.overlap < n]
    nfev, wins = 0, [0] * len(inits)
    prev_tail = None
    for s in (progress(starts, total=len(starts), desc="windows") if progress else starts):
        e = min(s + p.window, n)
        best = None
        for c, cand in enumerate(inits):
            x0 = cand[s:e].copy()
            if prev_tail is not None:  # continue from the previous window's solution where they overlap
                x0[: len(prev_tail)] = prev_tail[: e - s]
            prob = WindowProblem(rays[s:e, :, :2], weights[s:e], float(cam.K[0, 0]), dists, p.sigma_px, p.sigma_bone,
                                 sigma_step, float(np.median(x0[..., 2])))
            res = least_squares(prob.residuals, prob.to_params(x0), jac=prob.jac, method="trf", loss=p.loss,
                                x_scale="jac", max_nfev=p.max_nfev, tr_solver="lsmr", tr_options={"maxiter": p.lsmr_iterations})
            nfev += int(res.nfev)
            if best is None or res.cost < best[0]:
                best = (res.cost, c, prob.to_points(res.x))
        _, c, sol = best
        wins[c] += 1
        # cross-fade weights: ramps over the overlaps at both ends (not at the sequence's ends)
        w = np.ones(e - s)
        if s > 0 and p.overlap:
            k = min(p.overlap, e - s)
            w[:k] = np.linspace(0.0, 1.0, p.overlap + 2)[1:-1][:k]
        if e < n and p.overlap:
            w[-p.overlap:] = np.minimum(w[-p.overlap:], np.linspace(1.0, 0.0, p.overlap + 2)[1:-1])
        out[s:e] += w[:, None, None] * sol
        wsum[s:e] += w
        prev_tail = sol[-p.overlap:] if p.overlap else None
    out /= wsum[:, None, None]
    report.update(windows=len(starts), solver_evaluations=nfev, **fit_figures(out, rays, tracked, cam, dists, "final"))
    report.update({f"windows_from_init_smoothing_{sig:g}s": k for sig, k in zip(p.init_smoothing, wins)} if init is None else {})
    report.update(fit_figures(inits[0], rays, tracked, cam, dists, "init"))
    return out, report


def fit_figures(P: np.ndarray, rays: np.ndarray, tracked: np.ndarray, cam: Camera, dists: np.ndarray, tag: str) -> dict:
    """Reprojection RMS (px, tracked joints) and bone-length RMS deviation (mm) of a camera-frame solution."""
    proj = P[..., :2] / P[..., 2:3]
    err = np.linalg.norm((proj - rays[..., :2]) * cam.K[0, 0], axis=-1)[tracked]
    e = np.linalg.norm(P[:, PAIRS[:, 1]] - P[:, PAIRS[:, 0]], axis=-1) - dists
    return {f"{tag}_reprojection_rms_px": float(np.sqrt(np.mean(err**2))) if err.size else 0.0,
            f"{tag}_bone_rms_mm": float(np.sqrt(np.mean(e**2)) * 1000.0)}


@node(
    "reconstruct.sequence_lsq",
    version=1,
    inputs={"tracks": TRACKS2D, "camera": CAMERA, "body": BODY},
    outputs={"motion": MOTION, "report": report_port("reprojection and bone-length fit before/after, windows")},
    params=SequenceLsqParams,
)
def sequence_lsq(ctx, tracks, camera, body):
    """3D joints by windowed least squares (reprojection + bone lengths + smoothness), from ray_sphere's start."""
    p: SequenceLsqParams = ctx.params
    tr = read_tracks(tracks)
    cam = camera.camera()
    check_image_size(tr, cam)
    lengths = body_lengths(body)
    P, report = solve_sequence_lsq(tr.points, tr.tracked, cam, lengths, tr.fps, p, progress=ctx.progress)
    motion = motion_bundle(P, cam, tr)
    report["frames"] = int(tr.n_frames)
    return {"motion": motion, "report": report}
