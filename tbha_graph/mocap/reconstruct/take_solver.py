"""Solving the whole-take model (:mod:`.take_model`): Gauss–Newton normal equations in block form with the
analytic Jacobian (:mod:`.take_jacobian`), their banded solve, Levenberg–Marquardt, and the discrete search
over depth sides (a limb in front of or behind its parent gives the same image).

Everything in the camera frame (metres), vectorised over frames; shapes in each docstring.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.node import checkpoint
from ..runs import runs_of
from ..skeleton import N_JOINTS, PARENTS
from .take_jacobian import global_jacobian, joint_jacobian, length_jacobian, residual_jacobian
from .take_model import (ANKLES, J, N_BONES, PER_FRAME, TakeProblem, bone_directions,
                         pack_initial, unit)

#: Frames per chunk of the residuals-by-joints Jacobian in :func:`normal_equations` (bounds its memory)
JACOBIAN_CHUNK = 256


def lower_band(diag: np.ndarray, up1: np.ndarray, up2: np.ndarray) -> np.ndarray:
    """LAPACK's lower band storage ``(3 m, n m)`` (``ab[i - j, j] = A[i, j]``, ``3 m - 1`` subdiagonals) of the
    symmetric block-banded matrix with diagonal blocks ``diag`` and upper blocks ``up1`` (t, t+1), ``up2``
    (t, t+2), each ``(n, m, m)``. Block column t of the lower triangle, transposed, is the block row
    ``W_t = [diag_tᵀ | up1_t | up2_t | 0]`` ``(m, 4 m)``; the band's column ``t m + c`` is ``W_t[c, c:c + 3 m]``,
    read by a strided view (no index arrays) and copied once into Fortran order."""
    from numpy.lib.stride_tricks import as_strided

    n, m, _ = diag.shape
    W = np.empty((n, m, 4 * m))
    W[:, :, :m] = np.swapaxes(diag, 1, 2)
    W[:-1, :, m:2 * m] = up1[:-1]
    W[-1:, :, m:2 * m] = 0.0
    W[:-2, :, 2 * m:3 * m] = up2[:-2]
    W[-2:, :, 2 * m:3 * m] = 0.0
    W[:, :, 3 * m:] = 0.0
    st = W.strides
    skew = as_strided(W, shape=(n, m, 3 * m), strides=(st[0], st[1] + st[2], st[2]), writeable=False)  # [t, c, d] = W[t, c, c + d]
    cols = np.empty((n, m, 3 * m))  # [t, c, d]: the band's column t m + c, so C order here is Fortran order there
    cols[...] = skew
    return cols.reshape(n * m, 3 * m).T


@dataclass
class Normal:
    """Gauss–Newton normal equations ``A dx = -b`` of a take in block form: frame blocks ``diag`` ``(n, 33, 33)``,
    upper off-diagonal blocks ``up1`` (frame t with t+1) and ``up2`` (t with t+2) ``(n, 33, 33)``, frame
    gradient ``bf`` ``(n, 33)``; globals ``D`` ``(G, G)``, ``C`` ``(n, 33, G)`` (frames x globals), ``bg`` ``(G,)``."""

    diag: np.ndarray
    up1: np.ndarray
    up2: np.ndarray
    bf: np.ndarray
    D: np.ndarray
    C: np.ndarray
    bg: np.ndarray
    band: np.ndarray | None = None  # the frame block in LAPACK band storage, undamped (built by solve)

    def solve(self, lam: float) -> np.ndarray:
        """``dx`` (globals first, then frames) of ``(A + lam diag(A)) dx = -b``: banded Cholesky of the frame
        block (LAPACK ``dpbtrf``/``dpbtrs``: the blocks (t, t±1), (t, t±2) are a band of ``3 m - 1``
        subdiagonals, no fill-in outside it; :func:`lower_band`), Schur complement for the globals. Linear in
        the number of frames. Raises ``LinAlgError`` when the damped matrix is not positive definite."""
        from scipy.linalg import lapack  # imported where it is used: not paid by a cached run

        n, m = self.bf.shape
        N = n * m
        if self.band is None:  # built once per linearisation; each damping only changes its diagonal (row 0)
            self.band = lower_band(self.diag, self.up1, self.up2)
        ab = self.band.copy(order="F")
        ab[0] += lam * ab[0] + 1e-9
        chol, info = lapack.dpbtrf(ab, lower=1, overwrite_ab=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"frame matrix not positive definite (dpbtrf info {info})")

        def back(rhs: np.ndarray) -> np.ndarray:  # A^-1 rhs from the factor
            return lapack.dpbtrs(chol, rhs, lower=1)[0]

        bf = self.bf.reshape(N)
        G = self.D.shape[0]
        if G == 0:
            return -back(bf)
        C = self.C.reshape(N, G)
        Y = back(np.ascontiguousarray(np.concatenate([C, bf[:, None]], axis=1)))
        D = self.D + np.diag(lam * np.diag(self.D) + 1e-12)
        S = D - C.T @ Y[:, :G]
        dgl = np.linalg.solve(S, self.bg - C.T @ Y[:, G])
        dfr = Y[:, G] - Y[:, :G] @ dgl
        if not (np.isfinite(dgl).all() and np.isfinite(dfr).all()):
            raise np.linalg.LinAlgError("singular normal equations")
        return -np.concatenate([dgl, dfr])

    def globals_covariance(self) -> np.ndarray:
        """Covariance ``(G, G)`` of the globals (residuals in units of their sigmas): the inverse of the Schur
        complement of the frame block."""
        G = self.D.shape[0]
        if G == 0:
            return np.zeros((0, 0))
        zero = Normal(self.diag, self.up1, self.up2, np.zeros_like(self.bf), self.D, self.C, np.zeros(G))
        n, m = self.bf.shape
        cols = []
        for k in range(G):  # solve with unit gradients on each global: the columns of the inverse
            zero.bg = np.zeros(G)
            zero.bg[k] = -1.0
            cols.append(zero.solve(0.0)[:G])
        return np.array(cols).T


def _gram(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Per-frame ``Aᵀ B``: ``(t, r, i)``, ``(t, r, j)`` -> ``(t, i, j)`` (batched BLAS; ``einsum`` is ~20x slower here)."""
    return np.matmul(np.swapaxes(A, 1, 2), B)


def _gram_vec(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-frame ``Aᵀ v``: ``(t, r, i)``, ``(t, r)`` -> ``(t, i)``."""
    return np.matmul(np.swapaxes(A, 1, 2), v[..., None])[..., 0]


def normal_equations(prob: "TakeProblem", x: np.ndarray, r: np.ndarray | None = None) -> tuple[Normal, float]:
    """The Gauss–Newton normal equations of ``prob`` at ``x`` (blocks, see :class:`Normal`) and the cost;
    ``r``: ``prob.residuals(x)`` if the caller has it (not computed again).

    Jacobians are analytic (:mod:`.take_jacobian`): the frame unknowns' per frame (a frame's own residuals depend
    on its own unknowns only), accelerations and slides by the chain rule through the joints' differences, and
    the globals' for the whole residual vector."""
    n, G, F, m = prob.n, prob.n_glob, prob.n_frame_res, PER_FRAME
    g = prob.globals_of(x)
    fr = prob.frames_of(x)
    L = prob.lengths_of(g)
    P0 = prob.joints_from_frames(fr, L)
    nf = prob.floor(g)[0]
    if r is None:
        R0 = prob.frame_terms(P0, g)
        acc, slide = prob.coupled_terms(P0, nf)
    else:  # residuals() order: frame blocks, accelerations, slides, global priors
        n_acc = max(n - 2, 0) * N_JOINTS * 3
        R0 = r[: n * F].reshape(n, F)
        acc = r[n * F: n * F + n_acc].reshape(max(n - 2, 0), N_JOINTS * 3)
        slide = r[n * F + n_acc: n * F + n_acc + 2 * n].reshape(n, 2)
    dP = joint_jacobian(prob, fr, L).reshape(n, N_JOINTS * 3, m)
    diag = np.empty((n, m, m))
    bf = np.empty((n, m))
    chunks = []  # (frames, residual rows used, their Jacobian by the frame unknowns) per chunk, for C below
    pieces: list[dict] = []
    by_lengths = np.empty((n, F, N_BONES)) if prob.layout.free_lengths and G else None
    dPdL = length_jacobian(prob, P0, g) if by_lengths is not None else None
    for a in range(0, n, JACOBIAN_CHUNK):  # frames in chunks: the residuals-by-joints Jacobian is the largest array
        rows = slice(a, min(a + JACOBIAN_CHUNK, n))
        part: dict = {}
        dRdP = residual_jacobian(prob, P0[rows], g, part, rows).reshape(-1, F, N_JOINTS * 3)
        # rows zero on every frame of the chunk (a term not active here: the cover, the hanging limbs and most of
        # the silhouette's where the torso is seen) left out of the products: on the sample 57 of 149 are used
        live = np.flatnonzero(np.einsum("tri,tri->r", dRdP, dRdP))  # a sum of squares: 3x faster than any()
        dR = dRdP[:, live] @ dP[rows]
        diag[rows] = _gram(dR, dR)
        bf[rows] = _gram_vec(dR, R0[rows][:, live])
        if by_lengths is not None:
            by_lengths[rows] = dRdP @ dPdL[rows]
        chunks.append((rows, live, dR))
        pieces.append(part)
    parts = {k: np.concatenate([pc[k] for pc in pieces]) for k in pieces[0]} if pieces else {}
    up1 = np.zeros((n, m, m))
    up2 = np.zeros((n, m, m))
    if n > 2:  # window i (frames i, i+1, i+2, mask m_i) has Jacobian c_k S dP_(i+k) on frame i + k, c = (1, -2, 1):
        # one product per block diagonal, dP_tᵀ S² dP_(t+k) (k = 0, 1, 2), weighted by the windows that hold both
        s2 = prob.acc_scale[None, :, None] ** 2
        mask = prob.d.acc_mask()
        c = (1.0, -2.0, 1.0)
        dPs = dP * prob.acc_scale[None, :, None]  # S dP, once for the three block diagonals
        for k in range(3):
            bf[k:n - 2 + k] += c[k] * _gram_vec(dPs[k:n - 2 + k], acc)
        del dPs
        w0 = np.zeros(n)  # sum over the windows holding frame t of m_i c_k²
        for k in range(3):
            w0[k:n - 2 + k] += c[k] ** 2 * mask
        w1 = np.zeros(n - 1)  # pairs (t, t+1): windows i = t (c0 c1) and i = t - 1 (c1 c2)
        w1[:n - 2] += c[0] * c[1] * mask
        w1[1:] += c[1] * c[2] * mask
        dPs2 = dP * s2
        blk = _gram(dP, dPs2)  # each product scaled and added in place (no further temporaries)
        blk *= w0[:, None, None]
        diag += blk
        blk = _gram(dPs2[:-1], dP[1:])
        blk *= w1[:, None, None]
        up1[:-1] += blk
        blk = _gram(dPs2[:-2], dP[2:])
        blk *= (c[0] * c[2] * mask)[:, None, None]
        up2[:-2] += blk
        del blk, dPs2
    step, both = prob.slide_vectors(P0, nf)
    norm = np.linalg.norm(step, axis=-1, keepdims=True)
    u = np.where(both[..., None], step / np.maximum(norm, 1e-9), 0.0)
    u = u - (u @ nf)[..., None] * nf
    dPa = dP.reshape(n, N_JOINTS, 3, m)[:, ANKLES]
    d_now = np.einsum("tac,tacp->tap", u, dPa) / prob.w.sigma_slide  # (n, 2, m) on frame t
    d_prev = np.zeros_like(d_now)
    d_prev[1:] = -np.einsum("tac,tacp->tap", u[1:], dPa[:-1]) / prob.w.sigma_slide  # row t, on frame t-1
    diag += _gram(d_now, d_now)
    bf += _gram_vec(d_now, slide)
    if n > 1:
        diag[:-1] += _gram(d_prev[1:], d_prev[1:])
        up1[:-1] += _gram(d_prev[1:], d_now[1:])
        bf[:-1] += _gram_vec(d_prev[1:], slide[1:])
    r_full = np.concatenate([R0.ravel(), acc.ravel(), slide.ravel(), prob.global_terms(g)]) if r is None else r
    cost = 0.5 * float(r_full @ r_full)
    D = np.zeros((G, G))
    C = np.zeros((n, m, G))
    bg = np.zeros(G)
    if G:
        Jg = global_jacobian(prob, P0, g, parts, by_lengths)
        D = Jg.T @ Jg
        bg = Jg.T @ r_full
        Jf = Jg[: n * F].reshape(n, F, G)
        C = np.empty((n, m, G))
        for rows, live, dR in chunks:
            C[rows] = _gram(dR, Jf[rows][:, live])
        if n > 2 and prob.layout.free_lengths:  # accelerations depend on globals too when bone lengths are free
            Ja = Jg[n * F: n * F + (n - 2) * N_JOINTS * 3].reshape(n - 2, N_JOINTS * 3, G)
            s_acc = prob.acc_scale[None, :, None]
            am = prob.d.acc_mask()[:, None, None]
            for k, ck in enumerate((1.0, -2.0, 1.0)):
                C[k:n - 2 + k] += ck * _gram(dP[k:n - 2 + k] * s_acc, Ja * am)
        base = n * F + max(n - 2, 0) * N_JOINTS * 3
        Js = Jg[base: base + 2 * n].reshape(n, 2, G)
        C += _gram(d_now, Js)
        if n > 1:
            C[:-1] += _gram(d_prev[1:], Js[1:])
    return Normal(diag, up1, up2, bf, D, C, bg), cost


def levenberg_marquardt(prob: "TakeProblem", x0: np.ndarray, max_iterations: int = 30, tol: float = 1e-5):
    """Minimise ``0.5 |prob.residuals(x)|²`` by Levenberg–Marquardt on the block normal equations
    (:func:`normal_equations`, :meth:`Normal.solve`), re-centring the tangent references after every
    accepted step, and :func:`tbha_graph.core.node.checkpoint` before each iteration (an interrupted run stops
    here). Returns ``(x, cost, iterations, normal equations at the last linearisation)``."""
    from scipy.linalg import LinAlgError

    x = prob.recentre(x0)
    lam = 1e-3
    it = 0
    rel = 1.0
    ne, r = None, None
    for it in range(1, max_iterations + 1):
        checkpoint()  # Ctrl-C with --jobs > 1 stops the solve here (its node runs in a worker thread)
        ne = None  # the previous linearisation freed before the next is built
        ne, cost = normal_equations(prob, x, r)
        improved = False
        while lam < 1e10:
            try:
                dx = ne.solve(lam)
            except (LinAlgError, np.linalg.LinAlgError):
                lam *= 10
                continue
            xn = x + dx
            rn = prob.residuals(xn)
            cn = 0.5 * float(rn @ rn)
            if np.isfinite(cn) and cn < cost:
                rel = (cost - cn) / max(cost, 1e-12)
                x, cost, r = prob.recentre(xn), cn, rn  # re-centring changes the tangents' reference, not P
                lam = max(lam / 3.0, 1e-7)
                improved = True
                break
            lam *= 4.0
        if not improved or rel < tol:
            break
    if r is None:  # no step taken: the cost at the start (else it is the last accepted step's)
        r = prob.residuals(x)
    return x, 0.5 * float(r @ r), it, ne


def joints_cost(prob: TakeProblem, P: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Per-frame cost ``(n,)`` of joints ``P`` ``(n, 16, 3)`` (half squared residuals; accelerations and slides
    charged to the frame they end on)."""
    F = prob.frame_terms(P, g)
    acc, slide = prob.coupled_terms(P, prob.floor(g)[0])
    c = 0.5 * np.sum(F ** 2, axis=1) + 0.5 * np.sum(slide ** 2, axis=1)
    c[2:] += 0.5 * np.sum(acc ** 2, axis=1)
    return c


def reexpand(P: np.ndarray, old: np.ndarray, frames: np.ndarray, joints: list[int], lengths: np.ndarray) -> None:
    """Re-place ``joints`` (parents first) on ``frames`` of ``P`` (in place): each stays on its own camera ray
    (the ray through its position in ``old``), at its bone length from its (possibly moved) parent, on the
    same depth side of the parent as in ``old``."""
    for j in joints:
        a = PARENTS[j]
        u = unit(old[frames, j])
        side = np.sign(np.sum((old[frames, j] - old[frames, a]) * u, axis=-1))
        c = P[frames, a]
        uc = np.sum(u * c, axis=-1)
        D = lengths[j] ** 2 - (np.sum(c * c, axis=-1) - uc ** 2)
        P[frames, j] = (uc + side * np.sqrt(np.maximum(D, 0.0)))[:, None] * u


def descendants(j: int) -> list[int]:
    """Joints hanging below ``j`` (parents first)."""
    out, stack = [], [j]
    while stack:
        k = stack.pop(0)
        kids = [int(c) for c in np.flatnonzero(PARENTS == k)]
        out.extend(kids)
        stack.extend(kids)
    return out


def bone_cos(P: np.ndarray, j: int) -> np.ndarray:
    """Cosine ``(n,)`` between bone ``j`` (parent -> j) and the viewing ray to ``j``, ``P`` ``(n, 16, 3)`` camera
    frame: 0 in the image plane, +1 pointing straight away from the camera."""
    return np.sum(unit(P[:, j] - P[:, PARENTS[j]]) * unit(P[:, j]), axis=-1)


def dip_pieces(P: np.ndarray, j: int, seg: np.ndarray, max_cos: float, rise: float = 0.1) -> list[np.ndarray]:
    """``seg`` (a run of :func:`flip_segments`) cut where bone ``j`` comes back towards the image plane without
    crossing it: at each local minimum of ``|cos|`` (:func:`bone_cos`) at most ``max_cos`` and at least ``rise``
    below the run's highest ``|cos|`` on either side of it. A bone that really crosses the image plane there looks
    so to a solve that kept it on one side; each piece can then be mirrored on its own. Returns the pieces (of at
    least 2 frames; ``[seg]`` when there is no such dip)."""
    c = np.abs(bone_cos(P[seg], j))
    if len(c) < 3:
        return [seg]
    before = np.maximum.accumulate(c)[:-2]  # the highest |cos| up to the frame before each interior frame
    after = np.maximum.accumulate(c[::-1])[::-1][2:]  # ... and from the frame after it on
    mid = c[1:-1]
    dip = (mid <= max_cos) & (mid <= c[:-2]) & (mid < c[2:]) & (before - mid >= rise) & (after - mid >= rise)
    pieces = [piece for piece in np.split(seg, np.flatnonzero(dip) + 1) if len(piece) >= 2]
    return pieces if len(pieces) > 1 else [seg]


def flip_segments(P: np.ndarray, j: int, min_tilt: float = 0.12) -> list[np.ndarray]:
    """Frame runs ``[frames, ...]`` where bone ``j`` (parent -> j) points clearly out of the image plane
    (``|cos|`` between the bone and the viewing ray above ``min_tilt``): the segments whose depth side can be
    flipped as a whole (between runs the bone crosses the image plane, where a flip costs nothing)."""
    out = np.abs(bone_cos(P, j)) > min_tilt
    segs, start = [], None
    for k, o in enumerate(np.append(out, False)):
        if o and start is None:
            start = k
        elif not o and start is not None:
            segs.append(np.arange(start, k))
            start = None
    return segs


def solve_candidates(prob: TakeProblem, g: np.ndarray, wins: list, iterations: int) -> list:
    """Candidates for windows of a take re-optimised together: ``wins`` ``[(lo, hi, [Q, ...]), ...]``, each ``Q``
    ``(n, 16, 3)`` joints (camera frame) of which frames ``lo:hi`` are a candidate; all windows' candidates are
    solved for ``iterations`` LM steps, globals ``g`` held, as independent segments of one problem
    (``TakeData.breaks``). Returns per window ``(joints (k, hi - lo, 16, 3), costs (k,))`` of its ``k`` candidates
    (:func:`joints_cost` summed over the window)."""
    parts, idx, breaks = [], [], []
    for lo, hi, qs in wins:
        for Q in qs:
            parts.append(Q[lo:hi])
            idx.append(np.arange(lo, hi))
            breaks.append(np.r_[True, np.zeros(hi - lo - 1, dtype=bool)])
    Pst = np.concatenate(parts)
    data = prob.d.subset(np.concatenate(idx), breaks=np.concatenate(breaks))
    ref = bone_directions(Pst)
    wp = TakeProblem(data, ref, prob.floor(g)[0], prob.w, prob.offsets0, fixed_globals=g,
                     free_offsets=prob.layout.free_offsets, free_lengths=prob.layout.free_lengths)
    x, _, _, _ = levenberg_marquardt(wp, pack_initial(Pst, ref), iterations)
    Pout = wp.joints_from_frames(wp.frames_of(x), prob.lengths_of(g))
    cost = joints_cost(wp, Pout, g)
    out, start = [], 0
    for lo, hi, qs in wins:
        m, k = hi - lo, len(qs)
        out.append((Pout[start:start + k * m].reshape(k, m, N_JOINTS, 3), cost[start:start + k * m].reshape(k, m).sum(axis=1)))
        start += k * m
    return out


#: Bones whose depth side is searched together: both hip joints (the pelvis turned one way or the mirror way),
#: both shoulders (the thorax likewise), then each limb bone and the head on its own.
SIDE_GROUPS: tuple[tuple[int, ...], ...] = (
    (J["left_hip"], J["right_hip"]), (J["left_shoulder"], J["right_shoulder"]),
    (J["left_knee"],), (J["right_knee"],), (J["left_ankle"],), (J["right_ankle"],),
    (J["left_elbow"],), (J["right_elbow"],), (J["left_wrist"],), (J["right_wrist"],),
    (J["head"],),
)


def mirror(P: np.ndarray, frames: np.ndarray, group: tuple[int, ...], lengths: np.ndarray) -> np.ndarray:
    """``P`` with each joint of ``group`` moved to the other root of its ray-sphere on ``frames`` (the other
    depth side of its parent, same pixel) and the joints below it re-placed on their own sides."""
    trial = P.copy()
    for j in group:
        u = unit(P[frames, j])
        c = P[frames, PARENTS[j]]
        t_other = 2.0 * np.sum(u * c, axis=-1) - np.linalg.norm(P[frames, j], axis=-1)
        trial[frames, j] = t_other[:, None] * u
    below = [k for j in group for k in descendants(j)]
    reexpand(trial, P, frames, below, lengths)
    return trial


def disjoint_batches(windows: list) -> list[list]:
    """``windows`` ``[(lo, hi, ...), ...]`` put in batches of windows that do not overlap (each batch solved at once
    by :func:`solve_candidates`, the next on what it left): greedily by ``lo``, each batch taking every window that
    starts at or after the end of the one it took before."""
    pending, out = sorted(windows, key=lambda w: w[0]), []
    while pending:
        batch, rest, end = [], [], -1
        for w in pending:
            (batch if w[0] >= end else rest).append(w)
            end = w[1] if w[0] >= end else end
        out.append(batch)
        pending = rest
    return out


def search_sides_lm(prob: TakeProblem, P: np.ndarray, g: np.ndarray, iterations: int = 3, margin: int = 2,
                    groups: tuple[tuple[int, ...], ...] = SIDE_GROUPS, passes: int = 1,
                    split_cos: float | None = None) -> tuple[np.ndarray, int]:
    """Discrete search over depth sides with local re-optimisation: for each group of bones
    (:data:`SIDE_GROUPS`) and each out-of-plane run of frames (:func:`flip_segments`) the run is mirrored
    (:func:`mirror`); the current and the mirrored run (with ``margin`` frames either side) are re-optimised
    for ``iterations`` steps with the globals held — all windows of a group at once, as independent segments
    of one problem (``TakeData.breaks``) — and each mirror is kept when it ends cheaper than the current run.
    ``passes`` > 1 goes over the groups again, each group only where the mirrors kept since it was last searched
    changed the body (a limb's side decided before its torso was turned is decided again after). With
    ``split_cos``, once a group's whole runs are decided, each piece of a run that dips towards the image plane
    (:func:`dip_pieces`) is decided the same way on its own, in a window of its own (``margin`` frames either side;
    the pieces' windows in batches that do not overlap, :func:`disjoint_batches`). Returns the joints and the number of
    mirrors kept."""
    P = P.copy()
    L = prob.lengths_of(g)
    n = P.shape[0]
    kept = 0
    dirty = np.ones((len(groups), n), dtype=bool)  # frames where each group's sides are still to be (re)decided

    def decide(k: int, group: tuple[int, ...], wins: list) -> int:
        """Mirror ``group`` on each window's frames ``(lo, hi, seg)`` (windows apart), keep the cheaper (in ``P``)."""
        picks = solve_candidates(prob, g, [(lo, hi, [P, mirror(P, seg, group, L)]) for lo, hi, seg in wins], iterations)
        mirrored = 0
        for (lo, hi, _), (outs, cost) in zip(wins, picks):
            if cost[1] < cost[0]:
                P[lo:hi] = outs[1]
                mirrored += 1
                dirty[:, lo:hi] = True  # every group's sides on these frames: to decide again on the next pass
                dirty[k, lo:hi] = False
        return mirrored

    for _ in range(passes):
        for k, group in enumerate(groups):
            wins = []
            for seg in flip_segments(P, group[0]):
                if len(seg) < 2:
                    continue
                lo, hi = max(seg[0] - margin, 0), min(seg[-1] + 1 + margin, n)
                if dirty[k, lo:hi].any():
                    wins.append((lo, hi, seg))
            dirty[k] = False
            if not wins:
                continue
            kept += decide(k, group, wins)  # the whole runs
            if split_cos is not None:  # then each piece of a run that dips towards the image plane, on its own
                pieces = [(max(piece[0] - margin, 0), min(piece[-1] + 1 + margin, n), piece) for _, _, seg in wins
                          for piece in dip_pieces(P, group[0], seg, split_cos) if len(piece) < len(seg)]
                for batch in disjoint_batches(pieces):
                    kept += decide(k, group, batch)
    return P, kept


def turned(P: np.ndarray, frames: np.ndarray, up: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``P`` ``(n, 16, 3)`` (camera frame, metres) with the body on ``frames`` ``(k,)`` turned, rigidly, about the
    vertical ``up`` ``(3,)`` through its root by ``angle`` ``(k,)`` radians (right-handed about ``up``)."""
    up = unit(np.asarray(up, dtype=np.float64))
    root = P[frames, 0][:, None]
    X = P[frames] - root
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    X = X * c + np.cross(up, X) * s + (X @ up)[..., None] * up * (1.0 - c)  # Rodrigues about up
    out = P.copy()
    out[frames] = X + root
    return out


def turn_windows(mask: np.ndarray, window: int) -> list[np.ndarray]:
    """The runs of ``mask`` ``(n,)`` (:func:`runs_of`) cut into windows of about ``window`` frames (a run of
    ``m`` frames into ``round(m / window)`` nearly equal pieces, at least one)."""
    out = []
    for r in runs_of(mask):
        k = max(int(round(len(r) / window)), 1)
        out.extend(np.array_split(r, k))
    return out


def mirror_turn(P: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Angles ``(n,)`` radians about the vertical ``up`` ``(3,)`` that turn each frame's body ``P`` ``(n, 16, 3)``
    (camera frame) to the mirror of its heading about the viewing direction (the horizontal direction from the
    camera to the root): a front (the thorax's plus the pelvis's, :func:`.take_model.fronts`, made horizontal)
    at angle ``a`` from it goes to ``-a`` — seen side-on facing left becomes facing right."""
    from .take_model import fronts

    up = unit(np.asarray(up, dtype=np.float64))
    th, pe = fronts(P)
    f = th + pe
    f = unit(f - (f @ up)[:, None] * up)
    v = unit(P[:, 0] - (P[:, 0] @ up)[:, None] * up)
    return -2.0 * np.arctan2(np.cross(v, f) @ up, np.sum(v * f, axis=-1))


#: In :data:`TURN_ANGLES`: each frame turned to the mirror of its heading about the viewing direction (:func:`mirror_turn`)
MIRROR = -1.0
#: Window lengths (frames) of the turn search's passes (:func:`search_turns_lm`): the whole run first (0),
#: then pieces of this many frames
TURN_WINDOWS = (0, 24, 12)
#: LM steps on each pass's candidates in :func:`search_turns_lm`: measured on ``bench/labelling.py``'s six takes,
#: mean seq-MPJPE (focal estimated / given) 3: 168.9 / 180.2 mm, 6: 156.0 / 168.7, 10: 176.1 / 164.2
TURN_ITERATIONS = 6
#: The turns tried on each window, degrees about the vertical
TURN_ANGLES = (90.0, 180.0, 270.0, MIRROR)


def search_turns_lm(prob: TakeProblem, P: np.ndarray, g: np.ndarray, mask: np.ndarray, iterations: int = TURN_ITERATIONS,
                    margin: int = 3, windows: tuple[int, ...] = TURN_WINDOWS,
                    angles: tuple[float, ...] = TURN_ANGLES) -> tuple[np.ndarray, int]:
    """Discrete search over the body's heading where the image does not fix it (the torso unseen: a body seen
    side-on facing left or right, or turning round one way or the other, gives nearly the same outline and
    head). For each pass (``windows``: 0 = each run of ``mask`` ``(n,)`` whole, else pieces of that many
    frames, :func:`turn_windows`) and each window the whole body is turned about the vertical through its
    root by each of ``angles`` (degrees; :func:`turned`), ramped in over ``margin`` frames either side; the
    current and the turned copies of the window with its margins are re-optimised for ``iterations`` steps
    with the globals ``g`` held — all windows and angles of a pass at once, as independent segments of one
    problem (``TakeData.breaks``) — and the cheapest kept. Needs ``prob.d.up`` (the vertical); ``P``
    ``(n, 16, 3)`` camera frame, metres. Returns the joints and the number of turns kept."""
    if prob.d.up is None:
        return P, 0
    P = P.copy()
    n = P.shape[0]
    kept = 0
    for window in windows:
        wins = [(max(r[0] - margin, 0), min(r[-1] + 1 + margin, n), r)
                for r in (runs_of(mask) if window == 0 else turn_windows(mask, window))]
        if not wins:
            continue
        cands = []
        for lo, hi, run in wins:
            fr = np.arange(lo, hi)
            ramp = ramp_in(lo, hi, run, min(run[0] - lo, hi - 1 - run[-1]))
            turns = [mirror_turn(P[fr], prob.d.up) if a == MIRROR else np.full(hi - lo, np.radians(a)) for a in angles]
            cands.append((lo, hi, [P] + [turned(P, fr, prob.d.up, t * ramp) for t in turns]))
        kept += keep_cheapest(P, cands, solve_candidates(prob, g, cands, iterations))
    return P, kept


def ramp_in(lo: int, hi: int, run: np.ndarray, width: int) -> np.ndarray:
    """Weights ``(hi - lo,)`` in [0, 1] of frames ``lo:hi`` for a change made on ``run`` (frames inside it, whole) and
    ramped in over the margins either side: a margin frame ``k`` frames from the window's edge (1 at the edge) weighs
    ``k / (width + 1)``."""
    fr = np.arange(lo, hi)
    ramp = np.clip(np.minimum(fr - lo + 1, hi - fr) / (width + 1.0), 0.0, 1.0)
    ramp[(fr >= run[0]) & (fr <= run[-1])] = 1.0
    return ramp


def keep_cheapest(P: np.ndarray, cands: list, results: list) -> int:
    """Each window of ``cands`` (:func:`solve_candidates`' ``[(lo, hi, [Q, ...]), ...]``, the current joints first)
    set in ``P`` ``(n, 16, 3)`` to its cheapest re-optimised candidate from ``results`` (that function's answer), in
    place; returns how many windows took one other than the current joints."""
    kept = 0
    for (lo, hi, _), (outs, cost) in zip(cands, results):
        b = int(np.argmin(cost))
        if b > 0:
            P[lo:hi] = outs[b]
            kept += 1
    return kept


#: The lean search's passes (:func:`search_leans_lm`): windows of about this many frames over the whole take
LEAN_WINDOWS = (30, 15)
#: The leans tried on each window, degrees of the upper body about the hip line (forwards and backwards)
LEAN_ANGLES = (-16.0, -8.0, 8.0, 16.0)
#: LM steps on each pass's candidates in :func:`search_leans_lm`
LEAN_ITERATIONS = 3


#: The joints :func:`leaned` turns: the chest and every joint below it in the tree (spine, head, arms)
UPPER_BODY = np.array([J["chest"]] + descendants(J["chest"]))


def leaned(P: np.ndarray, frames: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``P`` ``(n, 16, 3)`` (camera frame, metres) with the upper body (the chest and every joint below it in the
    tree: spine, head, arms) on ``frames`` ``(k,)`` turned rigidly about the hips by ``angle`` ``(k,)`` radians around
    the hip line (left hip minus right hip: positive leans the body forwards, towards its front). Every bone keeps
    its length."""
    upper = UPPER_BODY
    axis = unit(P[frames, J["left_hip"]] - P[frames, J["right_hip"]])[:, None]
    root = P[frames, 0][:, None]
    X = P[frames][:, upper] - root
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    X = X * c + np.cross(axis, X) * s + np.sum(X * axis, axis=-1, keepdims=True) * axis * (1.0 - c)  # Rodrigues
    out = P.copy()
    sub = out[frames]
    sub[:, upper] = X + root
    out[frames] = sub
    return out


def search_leans_lm(prob: TakeProblem, P: np.ndarray, g: np.ndarray, windows: tuple[int, ...] = LEAN_WINDOWS,
                    angles: tuple[float, ...] = LEAN_ANGLES, iterations: int = LEAN_ITERATIONS,
                    margin: int = 2) -> tuple[np.ndarray, int]:
    """Discrete search over the upper body's lean towards or away from the camera, which the image fixes only
    through the spine's foreshortening (a torso leaning back with the hips a little lower projects nearly as one
    upright): for each pass (``windows``: the take cut into pieces of about that many frames) and each piece, the
    upper body leaned by each of ``angles`` (degrees, :func:`leaned`), ramped in over ``margin`` frames either side;
    the current and the leaned copies are re-optimised together for ``iterations`` LM steps with the globals ``g``
    held (:func:`solve_candidates`) and the cheapest kept. ``P`` ``(n, 16, 3)`` camera frame, metres. Returns the
    joints and the number of leans kept."""
    P = P.copy()
    n = P.shape[0]
    kept = 0
    for window in windows:
        cands = []
        for r in np.array_split(np.arange(n), max(int(round(n / window)), 1)):
            lo, hi = max(int(r[0]) - margin, 0), min(int(r[-1]) + 1 + margin, n)
            fr = np.arange(lo, hi)
            ramp = ramp_in(lo, hi, r, margin)
            cands.append((lo, hi, [P] + [leaned(P, fr, np.radians(a) * ramp) for a in angles]))
        kept += keep_cheapest(P, cands, solve_candidates(prob, g, cands, iterations))
    return P, kept
