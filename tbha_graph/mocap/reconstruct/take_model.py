"""The whole-take model the solver fits (:mod:`.solve_take`): a skeleton of known bone lengths seen by one
pinhole camera, with each tracked point modelled where the suit puts it (on the body surface, off the
joint centre).

Everything here is in the **camera frame** (metres, x right, y down, z forward; :mod:`..camera`) and
vectorised over frames. A take's unknowns are packed into one vector ``x``:

* globals: ``log f`` (focal, pixels), the floor plane (unit normal ``n`` as a tangent update of a
  reference normal, 2 values, and its offset ``d``: height above the floor of a camera-frame point ``X``
  is ``n·X + d``), and per tracked point its offset from its joint (``(along, out)`` metres, 2 values
  each: along the bone at the joint and outwards from the body's front);
* per frame: the root (hips) position ``(3,)`` and each bone's direction as a tangent update ``(a, b)``
  of a reference unit vector (15 bones), so every bone has its length exactly, by construction.

Residuals (each divided by its standard deviation, so the costs add up as negative log-likelihoods):
reprojection of every tracked point (pixels / ``sigma_px``, robust loss applied by the caller), second
differences of the joint positions (acceleration smoothness), near-rigidity of the torso (distances
between torso joints), knee and elbow hinge limits, floor contact (a planted ankle rests at its height
above the floor, no ankle goes below it) and a weak prior of the point offsets around their defaults.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..skeleton import JOINT_INDEX, N_JOINTS, PARENTS, topological_order

J = JOINT_INDEX
ORDER = topological_order()[1:]  # bones (by child joint) in an order where parents come first
N_BONES = N_JOINTS - 1
PER_FRAME = 3 + 2 * N_BONES

#: Joints whose "front" is the pelvis's (the rest use the thorax's).
PELVIS_SIDE = np.array([n in ("hips", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
                        for n in JOINT_INDEX])
#: The limb axis each point's "along" offset follows, as joint triples ``(a, m, b)``: the mean direction of
#: bones a->m and m->b (limbs: the limb through the joint; shoulders and hip joints: the upper arm / thigh;
#: torso and head: the bone ending at the joint, the spine for the hips).
_LIMB_AXES = {
    "hips": ("hips", "hips", "chest"), "left_shoulder": ("left_shoulder", "left_shoulder", "left_elbow"),
    "right_shoulder": ("right_shoulder", "right_shoulder", "right_elbow"), "left_hip": ("left_hip", "left_hip", "left_knee"),
    "right_hip": ("right_hip", "right_hip", "right_knee"), "left_elbow": ("left_shoulder", "left_elbow", "left_wrist"),
    "right_elbow": ("right_shoulder", "right_elbow", "right_wrist"), "left_knee": ("left_hip", "left_knee", "left_ankle"),
    "right_knee": ("right_hip", "right_knee", "right_ankle"), "left_wrist": ("left_elbow", "left_wrist", "left_wrist"),
    "right_wrist": ("right_elbow", "right_wrist", "right_wrist"), "left_ankle": ("left_knee", "left_ankle", "left_ankle"),
    "right_ankle": ("right_knee", "right_ankle", "right_ankle"),
}
AXIS_TRIPLES = np.array([[J[k] for k in _LIMB_AXES[n]] if n in _LIMB_AXES else [int(PARENTS[J[n]]), J[n], J[n]]
                         for n in JOINT_INDEX])

#: Default offset of each tracked point from its joint centre, metres, ``(N_JOINTS, 2)``: ``along`` the bone
#: ending at the joint and ``out`` of the body's front. Patches sit on the suit's surface in front of the
#: joint, about a limb radius out (left/right averages of the medians measured on the project's renderer
#: body, whose limb radii are those of an average adult); the head's point is the centre of the dark hair,
#: above the skull base. Starting values only: the solver estimates each offset from the take, with a prior
#: around these.
DEFAULT_POINT_OFFSETS = np.array([
    [0.000, 0.105],   # hips: on the belly
    [0.000, 0.103],   # chest
    [0.000, 0.085],   # neck
    [0.066, 0.000],   # head: centre of the (dark-haired) head above the skull base
    [0.000, 0.055],   # left_shoulder
    [0.000, 0.052],   # left_elbow
    [0.000, 0.038],   # left_wrist
    [0.000, 0.055],   # right_shoulder
    [0.000, 0.052],   # right_elbow
    [0.000, 0.038],   # right_wrist
    [0.000, 0.075],   # left_hip
    [0.000, 0.068],   # left_knee
    [-0.021, 0.048],  # left_ankle: on the lower shin
    [0.000, 0.075],   # right_hip
    [0.000, 0.068],   # right_knee
    [-0.021, 0.048],  # right_ankle
])

#: Joints of the near-rigid torso (their acceleration may have its own, tighter prior).
TORSO_JOINTS = np.array([J[n] for n in ("hips", "chest", "neck", "left_shoulder", "right_shoulder", "left_hip", "right_hip")])

#: Torso joint pairs kept at their rest distance (near-rigid torso), as index arrays.
TORSO_PAIRS = np.array([(J[a], J[b]) for a, b in (
    ("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"), ("left_shoulder", "hips"),
    ("right_shoulder", "hips"), ("left_hip", "chest"), ("right_hip", "chest"), ("left_shoulder", "left_hip"),
    ("right_shoulder", "right_hip"), ("neck", "hips"), ("left_hip", "neck"), ("right_hip", "neck"))])

#: Hinges: (joint, upper end, lower end, sign): ``sign * (inside of the bend · body forward) >= 0`` is natural
#: (knees bend backwards, elbows forwards).
HINGES = ((J["left_knee"], J["left_hip"], J["left_ankle"], -1.0), (J["right_knee"], J["right_hip"], J["right_ankle"], -1.0),
          (J["left_elbow"], J["left_shoulder"], J["left_wrist"], 1.0), (J["right_elbow"], J["right_shoulder"], J["right_wrist"], 1.0))
ANKLES = np.array([J["left_ankle"], J["right_ankle"]])


def unit(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis (zero vectors stay near zero)."""
    return v / np.maximum(np.sqrt(np.einsum("...i,...i->...", v, v)), 1e-9)[..., None]


def tangent_basis(ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(..., 3)`` perpendicular to unit ``ref`` ``(..., 3)`` and to each other."""
    helper = np.where(np.abs(ref[..., :1]) < 0.8, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    e1 = unit(np.cross(ref, helper))
    e2 = np.cross(ref, e1)
    return e1, e2


def fronts(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The thorax's and the pelvis's forward directions ``(..., n, 3)`` from joints ``(..., n, 16, 3)``
    (left × up, so +z of a body facing +z)."""
    def at(name):
        return P[..., J[name], :]
    thorax = unit(np.cross(at("left_shoulder") - at("right_shoulder"), at("neck") - at("chest")))
    pelvis = unit(np.cross(at("left_hip") - at("right_hip"), at("chest") - at("hips")))
    return thorax, pelvis


def point_positions(P: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Tracked points ``(..., n, 16, 3)``: each joint of ``P`` ``(..., n, 16, 3)`` moved by its ``offsets`` ``(16, 2)``
    (metres along the limb axis through it (:data:`AXIS_TRIPLES`), and out of the body's front made perpendicular to that bone)."""
    thorax, pelvis = fronts(P)
    front = np.where(PELVIS_SIDE[:, None], pelvis[..., None, :], thorax[..., None, :])
    a, m, b = (P[..., AXIS_TRIPLES[:, i], :] for i in range(3))
    axis = unit(unit(m - a) + unit(b - m))
    out = unit(front - np.sum(front * axis, axis=-1, keepdims=True) * axis)
    return P + offsets[:, 0:1] * axis + offsets[:, 1:2] * out


@dataclass
class TakeData:
    """What one solve sees: observed points ``(n, 16, 2)`` px, a weight per observation ``(n, 16)`` (0 = not
    tracked), bone lengths ``(16,)`` m, image centre ``(2,)`` px, frames per second, ankle height above the
    floor in metres, planted-ankle flags ``(n, 2)``."""

    points: np.ndarray
    weight: np.ndarray
    lengths: np.ndarray
    centre: np.ndarray
    fps: float
    ankle_height: float
    contact: np.ndarray
    rest_pairs: np.ndarray = field(default=None)  # (len(TORSO_PAIRS),) rest distances, metres
    #: ``(n,)`` bool or None: True where a new, independent segment starts (no acceleration or slide term
    #: links frame t to the frames before it); lets many separate windows be solved as one problem
    breaks: np.ndarray | None = None

    def acc_mask(self) -> np.ndarray:
        """``(n - 2,)`` 1.0 where the acceleration term of frames (t, t+1, t+2) lies inside one segment."""
        n = self.points.shape[0]
        if self.breaks is None or n < 3:
            return np.ones(max(n - 2, 0))
        b = np.asarray(self.breaks, dtype=bool)
        return (~(b[1:-1] | b[2:])).astype(np.float64)


@dataclass
class Weights:
    """Standard deviations of the model's residuals."""

    sigma_px: float = 1.0        # reprojection, pixels
    sigma_acc: float = 30.0      # joint acceleration, m/s^2
    sigma_acc_torso: float | None = None  # torso joints' acceleration (hips, chest, neck, shoulders, hip joints), m/s^2; None: sigma_acc
    sigma_torso: float = 0.05    # torso distances, metres (the real torso bends)
    sigma_hinge: float = 0.05    # wrong-way bending (unit vectors' dot product)
    sigma_floor: float = 0.01    # ankle below the floor / planted ankle off it, metres
    sigma_slide: float = 0.005   # planted ankle moving per frame, metres
    sigma_length: float = 0.03  # free bone lengths around the body's (log, i.e. relative)
    sigma_pose: float = 0.5      # weak pose prior: head along the neck (unit vectors)
    sigma_twist: float = 0.5     # pelvis facing as the thorax (unit vectors; 0.2 is about 11 degrees of twist)
    contact_band: float = 0.03   # a planted ankle may rise this far above its standing height (heel and toe roll), metres
    sigma_offset: float = 0.03   # point offsets around their defaults, metres
    robust_scale: float = 2.0    # reprojection residuals beyond this many sigmas count as soft-L1 (outliers)


def robust(r: np.ndarray, c: float) -> np.ndarray:
    """Residuals rescaled so their squares are the soft-L1 cost ``2 c² (√(1 + (r/c)²) − 1)`` (``≈ r²`` for small
    ``r``, linear beyond ``c``): the robust loss applied to reprojection only, not to the priors."""
    z = (r / c) ** 2
    return np.sign(r) * c * np.sqrt(2.0 * (np.sqrt(1.0 + z) - 1.0))


@dataclass
class Layout:
    """Where each unknown lives in ``x``; which globals are free."""

    n_frames: int
    free_offsets: bool = True
    free_lengths: bool = False

    @property
    def n_offsets(self) -> int:
        return 2 * N_JOINTS if self.free_offsets else 0

    @property
    def n_globals(self) -> int:
        return 1 + 3 + self.n_offsets + (N_BONES if self.free_lengths else 0)

    @property
    def size(self) -> int:
        return self.n_globals + self.n_frames * PER_FRAME


#: Residuals per frame that depend on that frame alone: reprojection (16 x 2), torso distances, hinges,
#: ankle below the floor (2), planted ankle off the floor (2), pose prior (head along the neck, 3; pelvis
#: facing where the thorax faces, 3).
N_FRAME_RES = N_JOINTS * 2 + len(TORSO_PAIRS) + len(HINGES) + 4 + 6


class TakeProblem:
    """Residuals and their Jacobian for one take (or window).

    ``x`` = globals (``n_glob`` values; none when ``fixed_globals`` is given) then ``n`` frames of
    :data:`PER_FRAME` values. Bone directions are tangent updates around ``ref`` ``(n, 15, 3)`` and the floor
    normal around ``n_ref`` ``(3,)``; :meth:`recentre` moves both references to the current solution.

    Residual vector: per-frame block ``(n, N_FRAME_RES)`` (frame-major), then accelerations
    ``(n - 2, 16 * 3)``, planted-ankle slides ``(n, 2)``, then global priors (point offsets, a known focal).
    """

    def __init__(self, data: TakeData, ref: np.ndarray, n_ref: np.ndarray, weights: Weights,
                 offsets0: np.ndarray, fixed_globals: np.ndarray | None = None, free_offsets: bool = True,
                 focal_prior: tuple[float, float] | None = None, free_lengths: bool = False):
        self.d, self.w = data, weights
        self.n = data.points.shape[0]
        self.offsets0 = offsets0
        self.layout = Layout(self.n, free_offsets, free_lengths)
        self.fixed_globals = None if fixed_globals is None else np.asarray(fixed_globals, dtype=np.float64)
        self.focal_prior = focal_prior  # (focal px, sigma of log f): a known focal length held (nearly) fixed
        self.n_glob = 0 if fixed_globals is not None else self.layout.n_globals
        self.set_refs(ref, n_ref)

    def set_refs(self, ref: np.ndarray, n_ref: np.ndarray) -> None:
        self.ref = ref
        self.e1, self.e2 = tangent_basis(ref)
        self.n_ref = unit(n_ref)
        f1, f2 = tangent_basis(self.n_ref[None])
        self.f1, self.f2 = f1[0], f2[0]

    # --- packing ----------------------------------------------------------------------------
    def globals_of(self, x: np.ndarray) -> np.ndarray:
        return self.fixed_globals if self.fixed_globals is not None else x[: self.n_glob]

    def floor(self, g: np.ndarray) -> tuple[np.ndarray, float]:
        return unit(self.n_ref + g[1] * self.f1 + g[2] * self.f2), float(g[3])

    def offsets(self, g: np.ndarray) -> np.ndarray:
        return self.offsets0 + (g[4:4 + 2 * N_JOINTS].reshape(N_JOINTS, 2) if self.layout.free_offsets else 0.0)

    def lengths_of(self, g: np.ndarray) -> np.ndarray:
        """Bone lengths ``(16,)`` metres: the body's, times ``exp`` of their log-updates when they are free."""
        if not self.layout.free_lengths:
            return self.d.lengths
        k = 4 + self.layout.n_offsets
        return self.d.lengths * np.exp(np.r_[0.0, g[k:k + N_BONES]])

    def frames_of(self, x: np.ndarray) -> np.ndarray:
        return x[self.n_glob:].reshape(self.n, PER_FRAME)

    def joints_from_frames(self, fr: np.ndarray, L: np.ndarray | None = None) -> np.ndarray:
        """Joint positions ``(..., n, 16, 3)`` camera frame from frame unknowns ``(..., n, PER_FRAME)`` (leading
        axes: e.g. perturbed copies of the take) and bone lengths ``L`` (the body's when not given)."""
        tangent = fr[..., 3:].reshape(fr.shape[:-1] + (N_BONES, 2))
        dirs = unit(self.ref + tangent[..., 0:1] * self.e1 + tangent[..., 1:2] * self.e2)
        P = np.empty(fr.shape[:-1] + (N_JOINTS, 3))
        P[..., 0, :] = fr[..., :3]
        L = self.d.lengths if L is None else L
        for j in ORDER:
            P[..., j, :] = P[..., PARENTS[j], :] + L[j] * dirs[..., j - 1, :]
        return P

    def solution(self, x: np.ndarray):
        """``(focal px, floor normal (3,), floor offset, point offsets (16, 2), joints (n, 16, 3))``."""
        g = self.globals_of(x)
        nf, d = self.floor(g)
        return float(np.exp(g[0])), nf, d, self.offsets(g), self.joints_from_frames(self.frames_of(x), self.lengths_of(g))

    # --- residuals ---------------------------------------------------------------------------
    def frame_terms(self, P: np.ndarray, g: np.ndarray) -> np.ndarray:
        """Per-frame residuals ``(..., n, N_FRAME_RES)`` of joints ``P`` ``(..., n, 16, 3)`` under globals ``g``
        (leading axes, e.g. perturbed copies of the take, broadcast against the take's data)."""
        w, d = self.w, self.d
        f = np.exp(g[0])
        nf, dfl = self.floor(g)
        Q = point_positions(P, self.offsets(g))
        z = np.maximum(Q[..., 2:3], 1e-3)
        uv = f * Q[..., :2] / z + d.centre
        rep = robust((uv - d.points) * (d.weight[..., None] / w.sigma_px), w.robust_scale).reshape(P.shape[:-2] + (-1,))
        dist = np.linalg.norm(P[..., TORSO_PAIRS[:, 0], :] - P[..., TORSO_PAIRS[:, 1], :], axis=-1)
        torso = (dist - d.rest_pairs) / w.sigma_torso
        thorax, pelvis = fronts(P)
        hin = []
        for jt, a, b, sign in HINGES:
            inside = unit(P[..., a, :] - P[..., jt, :]) + unit(P[..., b, :] - P[..., jt, :])
            fwd = pelvis if sign < 0 else thorax
            hin.append(np.minimum(sign * np.sum(inside * fwd, axis=-1), 0.0) / w.sigma_hinge)
        h = P[..., ANKLES, :] @ nf + dfl - d.ankle_height  # (..., n, 2) metres above where they rest
        below = np.minimum(h, 0.0) / w.sigma_floor
        on = np.where(d.contact, np.maximum(h - w.contact_band, 0.0), 0.0) / w.sigma_floor
        neck = P[..., J["neck"], :]
        head = (unit(P[..., J["head"], :] - neck) - unit(neck - P[..., J["chest"], :])) / w.sigma_pose
        twist = (pelvis - thorax) / w.sigma_twist
        return np.concatenate([rep, torso, np.stack(hin, axis=-1), below, on, head, twist], axis=-1)

    def slide_vectors(self, P: np.ndarray, nf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal steps ``(n, 2, 3)`` of the ankles since the previous frame (0 on frame 0) and the mask
        ``(n, 2)`` of steps between two planted frames."""
        step = np.zeros((self.n, 2, 3))
        both = np.zeros((self.n, 2), dtype=bool)
        if self.n > 1:
            s = P[1:, ANKLES] - P[:-1, ANKLES]
            step[1:] = s - (s @ nf)[..., None] * nf
            both[1:] = self.d.contact[1:] & self.d.contact[:-1]
            if self.d.breaks is not None:
                both &= ~np.asarray(self.d.breaks, dtype=bool)[:, None]
        return step, both

    @cached_property
    def acc_scale(self) -> np.ndarray:
        """``(48,)`` factor turning each joint coordinate's second difference (m per frame²) into sigma units."""
        sig = np.full(N_JOINTS, self.w.sigma_acc)
        if self.w.sigma_acc_torso is not None:
            sig[TORSO_JOINTS] = self.w.sigma_acc_torso
        return np.repeat(self.d.fps ** 2 / sig, 3)

    def coupled_terms(self, P: np.ndarray, nf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        acc = (P[2:] - 2.0 * P[1:-1] + P[:-2]).reshape(max(self.n - 2, 0), -1) * self.acc_scale
        acc = acc * self.d.acc_mask()[:, None]
        step, both = self.slide_vectors(P, nf)
        slide = np.where(both, np.linalg.norm(step, axis=-1), 0.0) / self.w.sigma_slide
        return acc, slide

    def global_terms(self, g: np.ndarray) -> np.ndarray:
        out = []
        if self.n_glob:
            if self.layout.free_offsets:
                out.append(((self.offsets(g) - self.offsets0) / self.w.sigma_offset).ravel())
            if self.layout.free_lengths:
                out.append(np.log(self.lengths_of(g)[1:] / self.d.lengths[1:]) / self.w.sigma_length)
            if self.focal_prior is not None:
                out.append(np.array([(g[0] - np.log(self.focal_prior[0])) / self.focal_prior[1]]))
        return np.concatenate(out) if out else np.zeros(0)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        g = self.globals_of(x)
        P = self.joints_from_frames(self.frames_of(x), self.lengths_of(g))
        acc, slide = self.coupled_terms(P, self.floor(g)[0])
        return np.concatenate([self.frame_terms(P, g).ravel(), acc.ravel(), slide.ravel(), self.global_terms(g)])

    def term_costs(self, x: np.ndarray) -> dict[str, float]:
        """Half sums of squares per kind of residual (for reports and tests)."""
        g = self.globals_of(x)
        P = self.joints_from_frames(self.frames_of(x), self.lengths_of(g))
        F = self.frame_terms(P, g)
        acc, slide = self.coupled_terms(P, self.floor(g)[0])
        k = np.cumsum([0, N_JOINTS * 2, len(TORSO_PAIRS), len(HINGES), 2, 2, 6])
        names = ("reprojection", "torso", "hinge", "below_floor", "contact", "pose")
        out = {nm: 0.5 * float(np.sum(F[:, k[i]:k[i + 1]] ** 2)) for i, nm in enumerate(names)}
        out.update(acceleration=0.5 * float(np.sum(acc ** 2)), slide=0.5 * float(np.sum(slide ** 2)),
                   priors=0.5 * float(np.sum(self.global_terms(g) ** 2)))
        return out

    def recentre(self, x: np.ndarray) -> np.ndarray:
        """Move the references to the current solution (tangents and the floor's update back to 0); returns
        the equivalent ``x``."""
        g = self.globals_of(x)
        P = self.joints_from_frames(self.frames_of(x), self.lengths_of(g))
        nf, _ = self.floor(g)
        ref = bone_directions(P)
        self.set_refs(ref, nf)
        out = x.copy()
        if self.n_glob:
            out[1:3] = 0.0
        out[self.n_glob:] = pack_initial(P, ref)
        return out


def lower_band(diag: np.ndarray, up1: np.ndarray, up2: np.ndarray) -> np.ndarray:
    """LAPACK's lower band storage ``(3 m, n m)`` (``ab[i - j, j] = A[i, j]``, ``3 m - 1`` subdiagonals) of the
    symmetric block-banded matrix with diagonal blocks ``diag`` and upper blocks ``up1`` (t, t+1), ``up2``
    (t, t+2), each ``(n, m, m)``. Each block column ``[diag; up1ᵀ; up2ᵀ]`` is read along its diagonals by a
    strided view (no index arrays), then copied once."""
    from numpy.lib.stride_tricks import as_strided

    n, m, _ = diag.shape
    K = np.zeros((n, 4 * m, m))  # block column t: rows of blocks (t, t), (t+1, t), (t+2, t), then zeros
    K[:, :m] = diag
    K[:-1, m:2 * m] = np.swapaxes(up1[:-1], 1, 2)
    K[:-2, 2 * m:3 * m] = np.swapaxes(up2[:-2], 1, 2)
    st = K.strides
    skew = as_strided(K, shape=(n, 3 * m, m), strides=(st[0], st[1], st[1] + st[2]), writeable=False)  # [t, d, c] = K[t, c + d, c]
    return np.asfortranarray(skew.transpose(1, 0, 2).reshape(3 * m, n * m))


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

    def solve(self, lam: float) -> np.ndarray:
        """``dx`` (globals first, then frames) of ``(A + lam diag(A)) dx = -b``: banded Cholesky of the frame
        block (LAPACK ``dpbtrf``/``dpbtrs``: the blocks (t, t±1), (t, t±2) are a band of ``3 m - 1``
        subdiagonals, no fill-in outside it; :func:`lower_band`), Schur complement for the globals. Linear in the number of
        frames. Raises ``LinAlgError`` when the damped matrix is not positive definite."""
        from scipy.linalg import lapack  # imported where it is used: not paid by a cached run

        n, m = self.bf.shape
        N = n * m
        diag = self.diag.copy()
        k = np.arange(m)
        diag[:, k, k] += lam * diag[:, k, k] + 1e-9
        chol, info = lapack.dpbtrf(lower_band(diag, self.up1, self.up2), lower=1, overwrite_ab=1)
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


def normal_equations(prob: "TakeProblem", x: np.ndarray) -> tuple[Normal, float]:
    """The Gauss–Newton normal equations of ``prob`` at ``x`` (blocks, see :class:`Normal`) and the cost.

    Jacobians are analytic (:mod:`.take_jacobian`): the frame unknowns' per frame (a frame's own residuals depend
    on its own unknowns only), accelerations and slides by the chain rule through the joints' differences, and
    the globals' for the whole residual vector."""
    from .take_jacobian import global_jacobian, joint_jacobian, residual_jacobian  # here: that module builds on this one

    n, G, F, m = prob.n, prob.n_glob, N_FRAME_RES, PER_FRAME
    g = prob.globals_of(x)
    fr = prob.frames_of(x)
    L = prob.lengths_of(g)
    P0 = prob.joints_from_frames(fr, L)
    R0 = prob.frame_terms(P0, g)
    nf = prob.floor(g)[0]
    dP = joint_jacobian(prob, fr, L).reshape(n, N_JOINTS * 3, m)
    parts: dict = {}
    dRdP = residual_jacobian(prob, P0, g, parts).reshape(n, F, N_JOINTS * 3)
    dR = dRdP @ dP  # (n, F, m)
    diag = _gram(dR, dR)
    bf = _gram_vec(dR, R0)
    up1 = np.zeros((n, m, m))
    up2 = np.zeros((n, m, m))
    acc, slide = prob.coupled_terms(P0, nf)
    if n > 2:
        s = prob.acc_scale
        dPs = dP * s[None, :, None]
        c = (1.0, -2.0, 1.0)
        mask = prob.d.acc_mask()[:, None, None]
        for k in range(3):
            bf[k:n - 2 + k] += c[k] * _gram_vec(dPs[k:n - 2 + k], acc)
            for l in range(k, 3):
                blk = mask * c[k] * c[l] * _gram(dPs[k:n - 2 + k], dPs[l:n - 2 + l])
                if l == k:
                    diag[k:n - 2 + k] += blk
                elif l - k == 1:
                    up1[k:n - 2 + k] += blk
                else:
                    up2[k:n - 2 + k] += blk
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
    r_full = np.concatenate([R0.ravel(), acc.ravel(), slide.ravel(), prob.global_terms(g)])
    cost = 0.5 * float(r_full @ r_full)
    D = np.zeros((G, G))
    C = np.zeros((n, m, G))
    bg = np.zeros(G)
    if G:
        Jg = global_jacobian(prob, P0, g, dRdP, parts)
        D = Jg.T @ Jg
        bg = Jg.T @ r_full
        Jf = Jg[: n * F].reshape(n, F, G)
        C = _gram(dR, Jf)
        if n > 2:  # accelerations depend on globals too when bone lengths are free
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
    accepted step. Returns ``(x, cost, iterations, normal equations at the last linearisation)``."""
    from scipy.linalg import LinAlgError

    x = prob.recentre(x0)
    lam = 1e-3
    it = 0
    rel = 1.0
    ne = None
    for it in range(1, max_iterations + 1):
        ne, cost = normal_equations(prob, x)
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
                x, cost = prob.recentre(xn), cn
                lam = max(lam / 3.0, 1e-7)
                improved = True
                break
            lam *= 4.0
        if not improved or rel < tol:
            break
    r = prob.residuals(x)
    return x, 0.5 * float(r @ r), it, ne


def pack_initial(P: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Frame unknowns ``(n * PER_FRAME,)`` reproducing joints ``P`` ``(n, 16, 3)`` around reference directions
    ``ref`` ``(n, 15, 3)`` (the bone directions of ``P`` itself give zero tangents)."""
    n = P.shape[0]
    e1, e2 = tangent_basis(ref)
    dirs = bone_directions(P)
    c = np.maximum(np.sum(dirs * ref, axis=-1), 1e-6)
    a = np.sum(dirs * e1, axis=-1) / c
    b = np.sum(dirs * e2, axis=-1) / c
    return np.concatenate([P[:, 0], np.stack([a, b], axis=-1).reshape(n, -1)], axis=1).ravel()


def bone_directions(P: np.ndarray) -> np.ndarray:
    """Unit bone directions ``(n, 15, 3)`` (parent -> child, bones in joint order 1..15)."""
    return unit(P[:, 1:] - P[:, PARENTS[1:]])


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


def flip_segments(P: np.ndarray, j: int, min_tilt: float = 0.12) -> list[np.ndarray]:
    """Frame runs ``[frames, ...]`` where bone ``j`` (parent -> j) points clearly out of the image plane
    (``|cos|`` between the bone and the viewing ray above ``min_tilt``): the segments whose depth side can be
    flipped as a whole (between runs the bone crosses the image plane, where a flip costs nothing)."""
    u = unit(P[:, j])
    cos = np.sum(unit(P[:, j] - P[:, PARENTS[j]]) * u, axis=-1)
    out = np.abs(cos) > min_tilt
    segs, start = [], None
    for k, o in enumerate(np.append(out, False)):
        if o and start is None:
            start = k
        elif not o and start is not None:
            segs.append(np.arange(start, k))
            start = None
    return segs


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


def search_sides_lm(prob: TakeProblem, P: np.ndarray, g: np.ndarray, iterations: int = 3, margin: int = 2,
                    groups: tuple[tuple[int, ...], ...] = SIDE_GROUPS) -> tuple[np.ndarray, int]:
    """Discrete search over depth sides with local re-optimisation: for each group of bones
    (:data:`SIDE_GROUPS`) and each out-of-plane run of frames (:func:`flip_segments`) the run is mirrored
    (:func:`mirror`); the current and the mirrored run (with ``margin`` frames either side) are re-optimised
    for ``iterations`` steps with the globals held — all windows of a group at once, as independent segments
    of one problem (``TakeData.breaks``) — and each mirror is kept when it ends cheaper than the current run.
    Returns the joints and the number of mirrors kept."""
    P = P.copy()
    nf = prob.floor(g)[0]
    L = prob.lengths_of(g)
    d = prob.d
    n = P.shape[0]
    kept = 0
    for group in groups:
        wins = []
        for seg in flip_segments(P, group[0]):
            if len(seg) < 2:
                continue
            wins.append((max(seg[0] - margin, 0), min(seg[-1] + 1 + margin, n), seg))
        if not wins:
            continue
        parts, idx, breaks = [], [], []
        for lo, hi, seg in wins:
            trial = mirror(P, seg, group, L)
            for Q in (P, trial):
                parts.append(Q[lo:hi])
                idx.append(np.arange(lo, hi))
                breaks.append(np.r_[True, np.zeros(hi - lo - 1, dtype=bool)])
        rows = np.concatenate(idx)
        Pst = np.concatenate(parts)
        data = TakeData(d.points[rows], d.weight[rows], d.lengths, d.centre, d.fps, d.ankle_height, d.contact[rows],
                        d.rest_pairs, breaks=np.concatenate(breaks))
        ref = bone_directions(Pst)
        wp = TakeProblem(data, ref, nf, prob.w, prob.offsets0, fixed_globals=g, free_offsets=prob.layout.free_offsets,
                         free_lengths=prob.layout.free_lengths)
        x, _, _, _ = levenberg_marquardt(wp, pack_initial(Pst, ref), iterations)
        Pout = wp.joints_from_frames(wp.frames_of(x), L)
        cost = joints_cost(wp, Pout, g)
        start = 0
        for lo, hi, seg in wins:
            m = hi - lo
            c_cur, c_new = cost[start:start + m].sum(), cost[start + m:start + 2 * m].sum()
            if c_new < c_cur:
                P[lo:hi] = Pout[start + m:start + 2 * m]
                kept += 1
            start += 2 * m
    return P, kept
