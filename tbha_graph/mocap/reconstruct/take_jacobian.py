"""Analytic Jacobian of the per-frame residuals of :class:`.take_model.TakeProblem` with respect to each
frame's own unknowns (root position and bone-direction tangents).

Two factors, both per frame and vectorised over frames:

* ``dP/dx`` ``(n, 48, 33)``: joints by frame unknowns. The root moves every joint; a bone's tangent ``(a, b)``
  turns its direction ``unit(ref + a e1 + b e2)`` and so moves the joint at its end and every joint below it
  by the bone's length times that turn (:func:`joint_jacobian`).
* ``dR/dP`` ``(n, F, 48)``: residuals by joint coordinates, from the closed-form derivatives of each term of
  :meth:`.take_model.TakeProblem.frame_terms` (unit vectors, cross products, the pinhole projection, the
  soft-L1 rescaling) (:func:`residual_jacobian`).

Their product is the frame block of the Jacobian that :func:`.take_solver.normal_equations` needs; a test
checks it against finite differences. Camera frame, metres; residuals in units of their sigmas.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import N_JOINTS, PARENTS
from .take_model import (ANKLES, AXIS_TRIPLES, HANG_BONES, HINGES, J, N_BONES, N_COVER, N_KP, PELVIS_JOINTS,
                         PELVIS_SIDE, PER_FRAME, SIL_PAIRS, THIGHS, THORAX_JOINTS, TORSO_PAIRS, TPOSE_PAIRS, TakeProblem, balance_residual,
                         bottom_residual, cross3,
                         cover_residuals, cover_segments, hang_residual, keypoint_targets, robust_slope, sil_residuals,
                         torso_unseen, unit,
                         unseen_points, upright_residual)

_EYE = np.eye(3)


def _subtree() -> np.ndarray:
    """``(16, 15)`` bool: joint k lies at or below the end of bone b (bone b ends at joint b + 1)."""
    below = np.zeros((N_JOINTS, N_BONES), dtype=bool)
    for k in range(1, N_JOINTS):
        j = k
        while j > 0:
            below[k, j - 1] = True
            j = int(PARENTS[j])
    return below


SUBTREE = _subtree()
#: The (joint, bone) pairs of :data:`SUBTREE` (joint k at or below the end of bone b), as two index arrays
_SUB_K, _SUB_B = np.nonzero(SUBTREE)


def skew(v: np.ndarray) -> np.ndarray:
    """``[v]x`` ``(..., 3, 3)`` with ``[v]x w = v x w``."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def unit_jacobian(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``unit(v)`` ``(..., 3)`` and its derivative ``(I - u uᵀ) / |v|`` ``(..., 3, 3)`` (as :func:`.take_model.unit`)."""
    norm = np.maximum(np.sqrt(np.einsum("...i,...i->...", v, v)), 1e-9)
    u = v / norm[..., None]
    D = u[..., :, None] * u[..., None, :]
    np.subtract(_EYE, D, out=D)
    D /= norm[..., None, None]
    return u, D


def front_jacobian(P: np.ndarray, joints: tuple[int, int, int, int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """A front (:func:`.take_model.front_of`) ``(n, 3)`` and its derivatives by ``P_l, P_r, P_up, P_lo``
    (four ``(n, 3, 3)``)."""
    l, r, up, lo = (P[:, k] for k in joints)
    a, b = l - r, up - lo
    f, Fc = unit_jacobian(cross3(a, b))
    da = Fc @ -skew(b)  # d(a x b) = -[b]x da + [a]x db
    db = Fc @ skew(a)
    return f, [da, -da, db, -db]


def add_through_front(out: np.ndarray, row: int, v: np.ndarray, d_front: list[np.ndarray], front_joints, scale: np.ndarray) -> None:
    """Add, in place, the derivative of ``v . front`` through the front (``v`` ``(n, 3)`` held fixed) to residual ``row``
    of ``out`` ``(n, rows, 16, 3)``: ``scale`` ``(n, 1)`` x ``v`` times each of the front's derivatives ``d_front``
    (:func:`front_jacobian`) on its joint of ``front_joints``. The hinge, hip-extension and facing-away terms share it."""
    for jj, Dj in zip(front_joints, d_front):
        out[:, row, jj] += (v[:, None, :] @ Dj)[:, 0] * scale


def joint_jacobian(prob: TakeProblem, fr: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``dP/dx`` ``(n, 16, 3, PER_FRAME)`` of :meth:`.take_model.TakeProblem.joints_from_frames` at frame
    unknowns ``fr`` ``(n, PER_FRAME)`` with bone lengths ``L`` ``(16,)``."""
    n = fr.shape[0]
    tangent = fr[:, 3:].reshape(n, N_BONES, 2)
    _, D = unit_jacobian(prob.ref + tangent[..., 0:1] * prob.e1 + tangent[..., 1:2] * prob.e2)  # (n, 15, 3, 3)
    turn = np.stack([D @ prob.e1[..., None], D @ prob.e2[..., None]], axis=-1)[..., 0, :]  # (n, 15, 3, 2)
    turn = turn * L[1:, None, None]
    out = np.zeros((n, N_JOINTS, 3, PER_FRAME))
    out[..., :3] = _EYE
    # joint k moves with bone b's turn where it hangs below it (SUBTREE), written pair by pair (a view of out)
    out[..., 3:].reshape(n, N_JOINTS, 3, N_BONES, 2)[:, _SUB_K, :, _SUB_B] = np.moveaxis(turn[:, _SUB_B], 0, 1)
    return out


def residual_jacobian(prob: TakeProblem, P: np.ndarray, g: np.ndarray, parts: dict | None = None,
                      rows: slice = slice(None)) -> np.ndarray:
    """``dR/dP`` ``(n, prob.n_frame_res, 16, 3)`` of :meth:`.take_model.TakeProblem.frame_terms` at joints ``P``
    ``(n, 16, 3)`` (the take's frames ``rows``: a chunk of it) under globals ``g``; ``parts`` (a dict, if
    given) receives the reprojection's pieces that :func:`global_jacobian` reuses."""
    w, d = prob.w, prob.d
    n = P.shape[0]
    out = np.zeros((n, prob.n_frame_res, N_JOINTS, 3))
    thorax, d_thorax = front_jacobian(P, THORAX_JOINTS)
    pelvis, d_pelvis = front_jacobian(P, PELVIS_JOINTS)
    row = 2 * N_JOINTS
    rep = _reprojection(prob, P, g, thorax, d_thorax, pelvis, d_pelvis, out, rows)
    if parts is not None:
        parts.update(rep)
    # torso distances
    for k, (a, b) in enumerate(TORSO_PAIRS):
        u = unit(P[:, a] - P[:, b]) / w.sigma_torso
        out[:, row + k, a] += u
        out[:, row + k, b] -= u
    row += len(TORSO_PAIRS)
    # hinges: min(sign * inside . fwd, 0)
    for k, (jt, a, b, sign) in enumerate(HINGES):
        ua, Ua = unit_jacobian(P[:, a] - P[:, jt])
        ub, Ub = unit_jacobian(P[:, b] - P[:, jt])
        inside = ua + ub
        fwd, dfwd, fj = (pelvis, d_pelvis, PELVIS_JOINTS) if sign < 0 else (thorax, d_thorax, THORAX_JOINTS)
        active = (sign * np.sum(inside * fwd, axis=-1) < 0.0)[:, None] * (sign / w.sigma_hinge)
        gi = (fwd[:, None, :] @ Ua)[:, 0] * active  # d/dP_a through inside
        gb = (fwd[:, None, :] @ Ub)[:, 0] * active
        out[:, row + k, a] += gi
        out[:, row + k, b] += gb
        out[:, row + k, jt] -= gi + gb
        add_through_front(out, row + k, inside, dfwd, fj, active)
    row += len(HINGES)
    # ankles below the floor / planted ankles above their band
    nf, dfl = prob.floor(g)
    h = P[:, ANKLES] @ nf + dfl - d.ankle_height
    for k, a in enumerate(ANKLES):
        out[:, row + k, a] = (h[:, k] < 0.0)[:, None] * nf / w.sigma_floor
        out[:, row + 2 + k, a] = (d.contact[rows, k] & (h[:, k] > w.contact_band))[:, None] * nf / w.sigma_floor
    row += 4
    # head along the neck
    _, Uh = unit_jacobian(P[:, J["head"]] - P[:, J["neck"]])
    _, Un = unit_jacobian(P[:, J["neck"]] - P[:, J["chest"]])
    for c in range(3):
        out[:, row + c, J["head"]] = Uh[:, c] / w.sigma_pose
        out[:, row + c, J["neck"]] = (-Uh[:, c] - Un[:, c]) / w.sigma_pose
        out[:, row + c, J["chest"]] = Un[:, c] / w.sigma_pose
    row += 3
    # twist: pelvis - thorax
    for jj, Dj in zip(PELVIS_JOINTS, d_pelvis):
        out[:, row:row + 3, jj] += Dj / w.sigma_twist
    for jj, Dj in zip(THORAX_JOINTS, d_thorax):
        out[:, row:row + 3, jj] -= Dj / w.sigma_twist
    row += 3
    # the hips' depth from the plane of the hip joints and the chest: s = (h - m) . unit(a x b), a = l - r,
    # b = c - m, m = (l + r) / 2; with g = N (h - m) (N the unit vector's derivative): ds = n.dh - n.dm - (g x b).da + (g x a).db
    if w.sigma_pelvis is not None:
        l, r, c, hp = (P[:, J[k]] for k in ("left_hip", "right_hip", "chest", "hips"))
        m = 0.5 * (l + r)
        a, b = l - r, c - m
        nn, N = unit_jacobian(cross3(a, b))
        gv = (N @ (hp - m)[..., None])[..., 0]
        gb, ga = cross3(gv, b), cross3(gv, a)
        out[:, row, J["hips"]] += nn / w.sigma_pelvis
        out[:, row, J["left_hip"]] += (-0.5 * nn - gb - 0.5 * ga) / w.sigma_pelvis
        out[:, row, J["right_hip"]] += (-0.5 * nn + gb - 0.5 * ga) / w.sigma_pelvis
        out[:, row, J["chest"]] += ga / w.sigma_pelvis
        row += 1
    # the hips over the feet: d dist = u . (dh - (1 - s) da - s db) (u across the floor, normal to the segment when
    # the nearest point is inside it, so moving along the segment changes nothing)
    if w.sigma_balance is not None:
        _, bal = balance_residual(P, d, w)
        k = (bal["on"] / w.sigma_balance)[:, None] * bal["u"]
        out[:, row, J["hips"]] += k
        out[:, row, J["left_ankle"]] -= (1.0 - bal["s"])[:, None] * k
        out[:, row, J["right_ankle"]] -= bal["s"][:, None] * k
        row += 1
    # the thighs behind the pelvis's front: min(u . f + c, 0) / sigma, u = unit(knee - hip joint), f the pelvis's front
    if w.sigma_hip is not None and d.away is not None:  # on the frames flagged away only
        hip_on = np.asarray(d.away, dtype=bool)[rows]
        for k, (hj, kn) in enumerate(THIGHS):
            u, U = unit_jacobian(P[:, kn] - P[:, hj])
            active = ((np.sum(u * pelvis, axis=-1) + w.hip_back_cos < 0.0) * hip_on / w.sigma_hip)[:, None]
            gk = (pelvis[:, None, :] @ U)[:, 0] * active
            out[:, row + k, kn] += gk
            out[:, row + k, hj] -= gk
            add_through_front(out, row + k, u, d_pelvis, PELVIS_JOINTS, active)
        row += len(THIGHS)
    if d.silhouette is not None:
        sil = _silhouette(prob, P, g, rows)
        for k, (a, b) in enumerate(SIL_PAIRS):
            out[:, row + k, a] += sil["dX"][:, k] * (1.0 if a == b else 0.5)
            if a != b:
                out[:, row + k, b] += sil["dX"][:, k] * 0.5
        row += len(SIL_PAIRS)  # support: the lower ankle's height above its band
        low = np.argmin(h, axis=1)
        act = (np.min(h, axis=1) > w.support_band)[:, None] * nf / w.sigma_support
        for k, a in enumerate(ANKLES):
            out[:, row, a] = act * (low == k)[:, None]
        row += 1  # facing away: max(front . to_camera, 0) on the frames flagged away
        away = np.zeros(n, bool) if d.away is None else np.asarray(d.away, dtype=bool)[rows]
        for k, (fr, dfr, fj, at) in enumerate(((thorax, d_thorax, THORAX_JOINTS, J["chest"]),
                                                (pelvis, d_pelvis, PELVIS_JOINTS, J["hips"]))):
            c, C = unit_jacobian(P[:, at])
            c, C = -c, -C
            on = (away & (np.sum(fr * c, axis=-1) + w.away_cos > 0.0))[:, None] / w.sigma_away
            add_through_front(out, row + k, c, dfr, fj, on)
            out[:, row + k, at] += (fr[:, None, :] @ C)[:, 0] * on
        row += 2  # the silhouette's bottom reached: d/dP_a of -rho(b - v(S(P_a)))
        bot = _bottom(prob, P, g, rows)
        proj = _EYE - nf[:, None] * nf[None, :]  # dS / dP_a
        for k, a in enumerate(ANKLES):
            out[:, row, a] += (bot["dr_dS"] @ proj) * (bot["k"] == k)[:, None]
        row += 1  # the outline covered: each sample's distance to its nearest segment
        cov = _cover(prob, P, g, rows)
        out[:, row:row + N_COVER] = cov["dP"]
        row += N_COVER  # the spine upright on head-only frames: d|h| = (h/|h|)ᵀ (I - up upᵀ) U (dP_neck - dP_hips)
        dr = d.subset(rows)  # this chunk's data, for the upright and hang terms
        _, up = upright_residual(P, dr, w)
        gh = up["h"] / np.maximum(up["s"], 1e-12)[:, None]
        gh = (gh - (gh @ up["up"])[:, None] * up["up"]) * (up["on"] / w.sigma_upright)[:, None]
        U = unit_jacobian(P[:, J["neck"]] - P[:, J["hips"]])[1]
        du = (gh[:, None, :] @ U)[:, 0]
        out[:, row, J["neck"]] += du
        out[:, row, J["hips"]] -= du
        row += 1  # the limbs hanging on head-only frames: d unit(P_b - P_a) = U (dP_b - dP_a)
        _, on = hang_residual(P, dr, w)
        if on.any():  # every hanging bone's unit-vector derivative at once, (n, bones, 3, 3)
            U = unit_jacobian(P[:, HANG_BONES] - P[:, PARENTS[HANG_BONES]])[1] * (on / w.sigma_hang)[:, None, None, None]
            for k, b in enumerate(HANG_BONES):
                out[:, row + 3 * k:row + 3 * k + 3, b] += U[:, k]
                out[:, row + 3 * k:row + 3 * k + 3, PARENTS[b]] -= U[:, k]
        if parts is not None:
            parts["bottom"] = np.concatenate([bot["dr_dS"], bot["dlogf"][:, None], bot["A"]], axis=1)
            parts["sil_dlogf"] = sil["dlogf"]
            parts["cover_dlogf"] = cov["dlogf"]
    if d.keypoints is not None:  # before the facing block: robust((uv - keypoint) w / sigma) per joint and axis
        row = prob.blocks["keypoints"].start
        kp = _keypoints(prob, P, g, rows)
        for j in range(N_JOINTS):
            out[:, row + 2 * j:row + 2 * j + 2, j] += kp["dP"][:, j]
        if parts is not None:
            parts["kp_dlogf"] = kp["dlogf"]
    if d.facing is not None:  # robust((front - hint) / sigma) per coordinate, thorax then pelvis
        row = prob.blocks["facing"].start
        hint = np.asarray(d.facing, dtype=np.float64)[rows]
        on = (np.linalg.norm(hint, axis=-1) > 0.5)  # (n, 2)
        for k, (fr, dfr, fj) in enumerate(((thorax, d_thorax, THORAX_JOINTS), (pelvis, d_pelvis, PELVIS_JOINTS))):
            e = (fr - hint[:, k]) * on[:, k, None] / w.sigma_facing
            slope = robust_slope(e, w.robust_scale) * on[:, k, None] / w.sigma_facing  # (n, 3)
            for jj, Dj in zip(fj, dfr):
                out[:, row + 3 * k:row + 3 * k + 3, jj] += slope[..., None] * Dj
    if d.holds_tpose:  # the last block: d (unit(P_b - P_a) - unit(P_e - P_c)) = U1 (dP_b - dP_a) - U2 (dP_e - dP_c)
        row = prob.blocks["tpose"].start
        on = np.asarray(d.tpose, dtype=np.float64)[rows] / w.sigma_tpose
        if on.any():
            a, b, c, e = (TPOSE_PAIRS[:, i] for i in range(4))
            U1 = unit_jacobian(P[:, b] - P[:, a])[1] * on[:, None, None, None]  # (n, pairs, 3, 3)
            U2 = unit_jacobian(P[:, e] - P[:, c])[1] * on[:, None, None, None]
            for k in range(len(TPOSE_PAIRS)):
                rk = slice(row + 3 * k, row + 3 * k + 3)
                out[:, rk, b[k]] += U1[:, k]
                out[:, rk, a[k]] -= U1[:, k]
                out[:, rk, e[k]] -= U2[:, k]
                out[:, rk, c[k]] += U2[:, k]
    return out


def _rep_columns(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Flat indices ``(k, 2, 3)`` into a frame's reprojection rows by joint coordinates (``(2 p + uv) 48 + 3 j + c``)
    of the (point, joint) pairs ``points``, ``joints`` ``(k,)``."""
    uv, c = np.arange(2)[:, None], np.arange(3)[None, :]
    return (2 * points[:, None, None] + uv) * (N_JOINTS * 3) + 3 * joints[:, None, None] + c


#: The reprojection Jacobian's (point, joint) pairs beyond each point's own joint (:func:`_reprojection`): the
#: limb axis' other ends (where they are other joints) and the four joints of each point's front
_LIVE_A = np.flatnonzero(AXIS_TRIPLES[:, 0] != AXIS_TRIPLES[:, 1])
_LIVE_B = np.flatnonzero(AXIS_TRIPLES[:, 2] != AXIS_TRIPLES[:, 1])
_REP_A = _rep_columns(_LIVE_A, AXIS_TRIPLES[_LIVE_A, 0])
_REP_B = _rep_columns(_LIVE_B, AXIS_TRIPLES[_LIVE_B, 2])
_PEL = np.flatnonzero(PELVIS_SIDE)
_THO = np.flatnonzero(~PELVIS_SIDE)
#: one scatter for the axis' terms: (p, p) for every point, then (p, a_p), (p, b_p) where live
_REP_AXIS = np.concatenate([_rep_columns(np.arange(N_JOINTS), np.arange(N_JOINTS)), _REP_A, _REP_B])
#: one for the fronts' terms: (pelvis-side points x the pelvis's 4 joints), then (the others x the thorax's 4)
_REP_FRONT = np.concatenate([_rep_columns(np.repeat(_PEL, 4), np.tile(PELVIS_JOINTS, len(_PEL))),
                             _rep_columns(np.repeat(_THO, 4), np.tile(THORAX_JOINTS, len(_THO)))]).reshape(N_JOINTS, 4, 2, 3)


def _pinhole(X: np.ndarray, f: float) -> np.ndarray:
    """``d uv / d X`` ``(..., 2, 3)`` of the projection ``uv = f X_xy / max(z, 1e-3) + c`` at points ``X`` ``(..., 3)``."""
    zc = X[..., 2]
    z = np.maximum(zc, 1e-3)
    out = np.zeros(X.shape[:-1] + (2, 3))
    out[..., 0, 0] = out[..., 1, 1] = f / z
    out[..., :, 2] = -f * X[..., :2] / (z ** 2)[..., None] * (zc >= 1e-3)[..., None]
    return out


def _cover(prob: TakeProblem, P: np.ndarray, g: np.ndarray, rows: slice) -> dict:
    """The cover residuals' (:func:`.take_model.cover_residuals`) derivatives by the joints ``dP``
    ``(n, N_COVER, 16, 3)`` and by ``log f`` ``dlogf`` ``(n, N_COVER)``: a sample's distance to its nearest
    segment moves with the segment's nearest point, ``(1 - t)`` of the image of end A and ``t`` of B's (the
    position along it is optimal, so its own change costs nothing), through the pinhole at each end and the
    ends' joint weights."""
    w, d = prob.w, prob.d
    f = np.exp(g[0])
    mask = torso_unseen(d.weight[rows])
    _, pc = cover_residuals(P, f, d.centre, d.silhouette, d.lengths, w, rows, mask=mask)
    n = P.shape[0]
    dP, dlogf = np.zeros((n, N_COVER, N_JOINTS, 3)), np.zeros((n, N_COVER))
    on = np.flatnonzero(mask)  # zero elsewhere: the term applies where the torso is unseen only
    if len(on):
        s, t, k = pc["s"][on], pc["t"][on], pc["drho"][on][..., None] * pc["g"][on]  # k: d r / d (nearest point), (m, K, 2)
        pick = lambda v: np.take_along_axis(v[on], s[..., None], axis=1)  # noqa: E731 - (n, 15, c) -> (m, K, c)
        ka, kb = (1.0 - t)[..., None] * k, t[..., None] * k
        GA = (ka[..., None, :] @ _pinhole(pick(pc["A"]), f))[..., 0, :]  # (m, K, 3)
        GB = (kb[..., None, :] @ _pinhole(pick(pc["B"]), f))[..., 0, :]
        a, b = cover_segments(d.lengths)
        dP[on] = np.einsum("nkj,nkc->nkjc", a[s], GA) + np.einsum("nkj,nkc->nkjc", b[s], GB)
        dlogf[on] = np.sum(ka * (pick(pc["ua"]) - d.centre) + kb * (pick(pc["ub"]) - d.centre), axis=-1)
    return {"dP": dP, "dlogf": dlogf}


def _bottom(prob: TakeProblem, P: np.ndarray, g: np.ndarray, rows: slice) -> dict:
    """The bottom residual's (:func:`.take_model.bottom_residual`) derivative by its floor point ``dr_dS``
    ``(n, 3)``, by ``log f`` ``dlogf`` ``(n,)``, the lower ankle ``k`` ``(n,)`` and its position ``A`` ``(n, 3)``."""
    w, d = prob.w, prob.d
    f = np.exp(g[0])
    nf, dfl = prob.floor(g)
    _, pc = bottom_residual(P, f, d.centre, nf, dfl, d.silhouette, w, rows)
    S, k = pc["S"], pc["k"]
    z = np.maximum(S[:, 2], 1e-3)
    dr = -pc["drho"][:, None] * _pinhole(S, f)[:, 1]  # d v / d S
    return {"dr_dS": dr, "dlogf": -pc["drho"] * f * S[:, 1] / z, "k": k, "A": P[:, ANKLES][np.arange(P.shape[0]), k]}


def _keypoints(prob: TakeProblem, P: np.ndarray, g: np.ndarray, rows: slice) -> dict:
    """The keypoint residuals' (:func:`.take_model.keypoint_residual`) derivatives by their joints ``dP``
    ``(n, 16, 2, 3)`` and by ``log f`` ``dlogf`` ``(n, N_KP)``: the soft-L1's slope times weight over sigma, times
    the pinhole's derivative (the left/right choice is piecewise constant)."""
    w, d = prob.w, prob.d.subset(rows)
    f = np.exp(g[0])
    z = np.maximum(P[..., 2:3], 1e-3)
    uv = f * P[..., :2] / z + d.centre
    target, wt = keypoint_targets(uv, d)
    k = wt[..., None] / w.sigma_kp
    slope = robust_slope((uv - target) * k, w.robust_scale) * k  # (n, 16, 2)
    return {"dP": slope[..., None] * _pinhole(P, f), "dlogf": (slope * (uv - d.centre)).reshape(P.shape[0], N_KP)}


def _silhouette(prob: TakeProblem, P: np.ndarray, g: np.ndarray, rows: slice) -> dict:
    """The silhouette residuals' derivatives by their points ``dX`` ``(n, N_SIL, 3)`` (a point is the mean of its
    two joints of :data:`.take_model.SIL_PAIRS`) and by ``log f`` ``dlogf`` ``(n, N_SIL)``: the field's image
    gradient times the pinhole projection's derivative, times the soft-L1's, over ``sigma_sil``."""
    w, d = prob.w, prob.d
    f = np.exp(g[0])
    _, pc = sil_residuals(P, f, d.centre, d.silhouette, w, rows, mask=unseen_points(d.weight[rows]))
    X = pc["X"]
    zc = X[..., 2]
    z = np.maximum(zc, 1e-3)
    k = (pc["drho"] / w.sigma_sil)[..., None] * pc["grad"]  # d r / d (u, v), (n, N_SIL, 2)
    dX = np.empty(X.shape)
    dX[..., :2] = k * (f / z)[..., None]
    dX[..., 2] = -np.sum(k * f * X[..., :2], axis=-1) / z ** 2 * (zc >= 1e-3)
    return {"dX": dX, "dlogf": np.sum(k * f * X[..., :2] / z[..., None], axis=-1)}


def _reprojection(prob: TakeProblem, P, g, thorax, d_thorax, pelvis, d_pelvis, out: np.ndarray, rows: slice) -> dict:
    """Write ``d rep / dP`` (rows ``0..31``: point j's u, v) into ``out`` ``(n, F, 16, 3)`` (zero there on entry);
    returns what the globals' derivatives reuse: ``Gq`` (d rep / d point, ``(n, 16, 2, 3)``), the points' ``axis``
    and ``out`` directions ``(n, 16, 3)`` and ``dlogf`` (d rep / d log f, ``(n, 16, 2)``)."""
    w, d = prob.w, prob.d
    n = P.shape[0]
    f = np.exp(g[0])
    offs = prob.offsets(g)
    o_al, o_out = offs[:, 0][None, :, None, None], offs[:, 1][None, :, None, None]
    # limb axis through each point: unit(unit(m - a) + unit(b - m)); a == m or b == m gives a constant zero term
    a_i, m_i, b_i = AXIS_TRIPLES[:, 0], AXIS_TRIPLES[:, 1], AXIS_TRIPLES[:, 2]
    u1, U1 = unit_jacobian(P[:, m_i] - P[:, a_i])
    u2, U2 = unit_jacobian(P[:, b_i] - P[:, m_i])
    live1 = (a_i != m_i)[None, :, None, None]
    live2 = (b_i != m_i)[None, :, None, None]
    U1, U2 = U1 * live1, U2 * live2
    u1, u2 = u1 * live1[..., 0], u2 * live2[..., 0]
    axis, A = unit_jacobian(u1 + u2)  # (n, 16, 3), (n, 16, 3, 3)
    side = PELVIS_SIDE[None, :, None]
    front = np.where(side, pelvis[:, None], thorax[:, None])
    fa = np.sum(front * axis, axis=-1)
    outv, O = unit_jacobian(front - fa[..., None] * axis)
    proj = _EYE - axis[..., :, None] * axis[..., None, :]  # d out-vector / d front (before O)
    M = axis[..., :, None] * front[..., None, :] + fa[..., None, None] * _EYE  # minus d out-vector / d axis
    np.negative(M, out=M)  # d out-vector / d axis
    d_axis = o_al * A + o_out * (O @ M @ A)  # dQ per unit change of the axis' sum s, (n, 16, 3, 3)
    Q = P + offs[:, 0][None, :, None] * axis + offs[:, 1][None, :, None] * outv
    # d rep / dQ: soft-L1 of (f Q_xy / z + c - obs) * weight / sigma
    z = np.maximum(Q[..., 2], 1e-3)
    s = d.weight[rows] / w.sigma_px  # (n, 16)
    e = ((f * Q[..., :2] / z[..., None] + d.centre) - d.points[rows]) * s[..., None]
    drho = robust_slope(e, w.robust_scale)
    Gq = (drho * s[..., None])[..., None] * _pinhole(Q, f)  # (n, 16, 2, 3)
    flat = out.reshape(n, -1)  # point p's rows (2 p + uv) by joint j's coordinate c: column (2 p + uv) 48 + 3 j + c
    # the point's own joint (m == j), the limb axis' other ends: distinct (point, joint) pairs, one scatter (the
    # first write into ``out``'s zeros: assigned, no read-add-write)
    flat[:, _REP_AXIS] = np.concatenate([Gq @ (np.broadcast_to(_EYE, (n, N_JOINTS, 3, 3)) + d_axis @ (-U2 + U1)),
                                          (Gq @ (d_axis @ -U1))[:, _LIVE_A], (Gq @ (d_axis @ U2))[:, _LIVE_B]], axis=1)
    # the front's four joints: point j's rows += Gq_j o_out_j O_j proj_j D_k (D_k of its front), the first three
    # factors once for all four joints; each point's rows go to its own front's joints (added after the axis' terms)
    GqOP = Gq @ (o_out * (O @ proj))  # (n, 16, 2, 3)
    flat[:, _REP_FRONT] += np.concatenate([GqOP[:, _PEL, None] @ np.stack(d_pelvis, axis=1)[:, None],
                                           GqOP[:, _THO, None] @ np.stack(d_thorax, axis=1)[:, None]], axis=1)
    return {"Gq": Gq, "axis": axis, "out": outv, "dlogf": drho * s[..., None] * (f * Q[..., :2] / z[..., None])}


def length_jacobian(prob: TakeProblem, P: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``dP / d log L`` ``(n, 48, 15)``: a bone made longer moves every joint below it along the bone."""
    n = P.shape[0]
    dirs = unit(P[:, 1:] - P[:, PARENTS[1:]])  # (n, 15, 3)
    L = prob.lengths_of(g)
    return (SUBTREE[None, :, None, :] * (L[1:] * np.swapaxes(dirs, 1, 2))[:, None]).reshape(n, N_JOINTS * 3, N_BONES)


def global_jacobian(prob: TakeProblem, P: np.ndarray, g: np.ndarray, parts: dict,
                    frame_by_lengths: np.ndarray | None = None) -> np.ndarray:
    """Jacobian ``(n_residuals, G)`` of the whole residual vector (:meth:`.take_model.TakeProblem.residuals`
    order: frame blocks, accelerations, slides, global priors) by the globals: ``log f``, the floor's tangent
    update (2) and offset, the point offsets (32, when free) and the bone-length log-updates (15, when free).
    ``P`` ``(n, 16, 3)`` joints, ``parts`` from :func:`residual_jacobian`; with free lengths
    ``frame_by_lengths`` ``(n, F, 15)`` = ``dR/dP`` times :func:`length_jacobian` (the caller has ``dR/dP``)."""
    w, d, lay = prob.w, prob.d, prob.layout
    n, F, G = P.shape[0], prob.n_frame_res, prob.n_glob
    n_acc = max(n - 2, 0)
    Jf = np.zeros((n, F, G))
    Ja = np.zeros((n_acc, N_JOINTS * 3, G))
    Js = np.zeros((n, 2, G))
    Jp = []
    # focal: the image scales about the centre
    Jf[:, prob.blocks["reprojection"], 0] = parts["dlogf"].reshape(n, -1)
    if "sil_dlogf" in parts:  # the silhouette's points scale about the centre too; the support moves with the floor
        sil = prob.blocks["silhouette"].start
        Jf[:, sil:sil + len(SIL_PAIRS), 0] = parts["sil_dlogf"]
        Jf[:, prob.blocks["cover"], 0] = parts["cover_dlogf"]
    if "kp_dlogf" in parts:  # the detector's keypoints scale about the centre too
        Jf[:, prob.blocks["keypoints"], 0] = parts["kp_dlogf"]
    # floor: ankle heights h = P_a . nf + d and the slides' horizontal projection
    f1 = unit_jacobian(prob.n_ref + g[1] * prob.f1 + g[2] * prob.f2)[1] @ np.stack([prob.f1, prob.f2], axis=1)  # (3, 2)
    nf, dfl = prob.floor(g)
    h = P[:, ANKLES] @ nf + dfl - d.ankle_height
    below = (h < 0.0) / w.sigma_floor
    above = (d.contact & (h > w.contact_band)) / w.sigma_floor
    dh = np.concatenate([P[:, ANKLES] @ f1, np.ones((n, 2, 1))], axis=-1)  # (n, 2, 3): d h / d (g1, g2, d)
    Jf[:, prob.blocks["below_floor"], 1:4] = below[..., None] * dh
    Jf[:, prob.blocks["contact"], 1:4] = above[..., None] * dh
    if d.silhouette is not None:
        low = np.argmin(h, axis=1)
        act = (np.min(h, axis=1) > w.support_band) / w.sigma_support
        Jf[:, prob.blocks["silhouette"].start + len(SIL_PAIRS), 1:4] = act[:, None] * dh[np.arange(n), low]
        # bottom: S = A - (A.n + d) n; dS/d(g1, g2) = -(n A^T + (A.n + d) I) dn/d(g1, g2), dS/dd = -n
        bt = parts["bottom"]
        dr_dS, dlf, A = bt[:, :3], bt[:, 3], bt[:, 4:]
        hA = A @ nf + dfl
        dSdn = -(nf[None, :, None] * A[:, None, :] + hA[:, None, None] * _EYE)  # (n, 3, 3)
        col = prob.blocks["silhouette"].stop - 1
        Jf[:, col, 0] = dlf
        Jf[:, col, 1:3] = ((dr_dS[:, None, :] @ dSdn)[:, 0]) @ f1
        Jf[:, col, 3] = -(dr_dS @ nf)
    step, both = prob.slide_vectors(P, nf)
    u = np.where(both[..., None], step / np.maximum(np.linalg.norm(step, axis=-1, keepdims=True), 1e-9), 0.0)
    s_raw = np.zeros_like(step)
    s_raw[1:] = P[1:, ANKLES] - P[:-1, ANKLES]
    # slide = |s - (s.nf) nf| / sigma; u is horizontal, so d slide = -(s.nf) (u . d nf) / sigma
    Js[..., 1:3] = -(np.sum(s_raw * nf, axis=-1)[..., None] * (u @ f1)) / w.sigma_slide
    k = 4
    if lay.free_offsets:  # point j moved along its axis / out of the body: d rep = Gq_j (axis_j | out_j)
        Gq = parts["Gq"]
        along = (Gq @ parts["axis"][..., None])[..., 0]  # (n, 16, 2)
        outw = (Gq @ parts["out"][..., None])[..., 0]
        cols = k + 2 * np.arange(N_JOINTS)
        for j in range(N_JOINTS):
            Jf[:, 2 * j:2 * j + 2, cols[j]] = along[:, j]
            Jf[:, 2 * j:2 * j + 2, cols[j] + 1] = outw[:, j]
        Jp.append(np.eye(2 * N_JOINTS) / w.sigma_offset)
        k += 2 * N_JOINTS
    if lay.free_lengths:  # bone b longer: every joint below it moves along the bone
        dPdL = length_jacobian(prob, P, g)
        Jf[..., k:k + N_BONES] = frame_by_lengths
        if n_acc:
            second = dPdL[2:] - 2.0 * dPdL[1:-1] + dPdL[:-2]
            Ja[..., k:k + N_BONES] = second * prob.acc_scale[None, :, None] * d.acc_mask()[:, None, None]
        dA = dPdL.reshape(n, N_JOINTS, 3, N_BONES)[:, ANKLES]  # (n, 2, 3, 15)
        ds = np.zeros_like(dA)
        ds[1:] = dA[1:] - dA[:-1]
        Js[..., k:k + N_BONES] = np.einsum("tac,tacb->tab", u, ds) / w.sigma_slide
        Jp.append(np.eye(N_BONES) / w.sigma_length)
        k += N_BONES
    prior = np.zeros((0, G))
    if Jp:
        prior = np.zeros((sum(b.shape[0] for b in Jp), G))
        r0, c0 = 0, 4
        for b in Jp:
            prior[r0:r0 + b.shape[0], c0:c0 + b.shape[1]] = b
            r0 += b.shape[0]
            c0 += b.shape[1]
    if prob.focal_prior is not None:
        fp = np.zeros((1, G))
        fp[0, 0] = 1.0 / prob.focal_prior[1]
        prior = np.concatenate([prior, fp])
    if prob.floor_prior is not None:  # the floor's normal against the room's: d normal / d (g1, g2)
        up = np.zeros((3, G))
        up[:, 1:3] = f1 / prob.floor_prior[1]
        prior = np.concatenate([prior, up])
    return np.concatenate([Jf.reshape(n * F, G), Ja.reshape(-1, G), Js.reshape(n * 2, G), prior])
