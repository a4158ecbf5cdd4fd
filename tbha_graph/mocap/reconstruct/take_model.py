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
above the floor, no ankle goes below it) and a weak prior of the point offsets around their defaults; with the
actor's silhouette (:class:`SilhouetteField`), the joints inside it (:func:`sil_residuals`), the feet on its lowest
row (:func:`bottom_residual`), the torso facing away and upright (:func:`upright_residual`) where only the head
is tracked, and the model covering its
outline where the torso is not seen (:func:`cover_residuals`); there too, optionally, the limbs hanging
(:func:`hang_residual`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..skeleton import JOINT_INDEX, N_JOINTS, PARENTS, TORSO_JOINTS, topological_order, torso_unseen

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


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of 3-vectors along the last axis (broadcast): ``np.cross``'s arithmetic, bit for bit, without its
    axis moves (which cost more than the products on the solver's arrays of a few hundred frames)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def tangent_basis(ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(..., 3)`` perpendicular to unit ``ref`` ``(..., 3)`` and to each other."""
    helper = np.where(np.abs(ref[..., :1]) < 0.8, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    e1 = unit(cross3(ref, helper))
    e2 = cross3(ref, e1)
    return e1, e2


#: Joints of the thorax's and the pelvis's front ``(l, r, up, lo)``: front = unit((l - r) x (up - lo)).
THORAX_JOINTS = (J["left_shoulder"], J["right_shoulder"], J["neck"], J["chest"])
PELVIS_JOINTS = (J["left_hip"], J["right_hip"], J["chest"], J["hips"])


def front_of(P: np.ndarray, joints: tuple[int, int, int, int]) -> np.ndarray:
    """The front ``unit((P_l - P_r) x (P_up - P_lo))`` ``(..., n, 3)`` of joints ``(..., n, 16, 3)``."""
    l, r, up, lo = (P[..., k, :] for k in joints)
    return unit(cross3(l - r, up - lo))


def fronts(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The thorax's and the pelvis's forward directions ``(..., n, 3)`` from joints ``(..., n, 16, 3)``
    (left × up, so +z of a body facing +z)."""
    return front_of(P, THORAX_JOINTS), front_of(P, PELVIS_JOINTS)


def pelvis_depth(P: np.ndarray) -> np.ndarray:
    """How far the hips joint lies in front of the plane through the hip joints and the chest ``(..., n)`` metres
    (negative: behind it), along that plane's normal ``(l - r) x (chest - (l + r) / 2)`` (forward for a body facing
    +z), from joints ``P`` ``(..., n, 16, 3)``. The bones' lengths and the torso's distances leave it free to fold
    either way (the rest T-pose has it flat); the CMU skeletons of the renders have it 28-35 mm behind."""
    l, r, c, h = (P[..., J[k], :] for k in ("left_hip", "right_hip", "chest", "hips"))
    m = 0.5 * (l + r)
    return np.sum((h - m) * unit(cross3(l - r, c - m)), axis=-1)


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
    #: the actor's silhouette (:class:`SilhouetteField`, its ``index`` one row per frame here) or None: no term
    silhouette: "SilhouetteField | None" = None
    #: ``(3,)`` the vertical (unit, camera frame: the floor's normal when the problem was made) or None
    up: np.ndarray | None = None
    #: ``(n,)`` bool or None: frames where the actor is seen (head tracked) but none of the torso's patches is —
    #: the suit's patches are on the body's front, so the torso faces away (used with a silhouette only)
    away: np.ndarray | None = None
    #: ``(n, 2, 3)`` or None: the thorax's and the pelvis's front (unit, camera frame) as a detector's own 3D shows
    #: them (zero vectors where it shows none), a prior on which way the torso faces (:func:`facing_residual`)
    facing: np.ndarray | None = None
    #: ``(n, 16, 2)`` px or None: a detector's keypoints (joint centres, left and right possibly swapped), used
    #: where the suit's own points are lost (:func:`keypoint_residual`), with ``kp_weight`` ``(n, 16)``: the
    #: detector's confidence (0 = none)
    keypoints: np.ndarray | None = None
    kp_weight: np.ndarray | None = None
    #: ``(n,)`` bool or None: the take's opening T-pose as the image shows it (:func:`..tpose.find_tpose`),
    #: where the limbs are held straight and the arms out (:func:`tpose_residual`)
    tpose: np.ndarray | None = None

    def subset(self, rows, breaks: np.ndarray | None = None) -> "TakeData":
        """The data of the frames ``rows`` (slice or index array), with ``breaks`` for them."""
        return TakeData(self.points[rows], self.weight[rows], self.lengths, self.centre, self.fps, self.ankle_height,
                        self.contact[rows], self.rest_pairs, breaks=breaks,
                        silhouette=None if self.silhouette is None else self.silhouette.subset(rows),
                        away=None if self.away is None else np.asarray(self.away)[rows], up=self.up,
                        facing=None if self.facing is None else np.asarray(self.facing)[rows],
                        keypoints=None if self.keypoints is None else np.asarray(self.keypoints)[rows],
                        kp_weight=None if self.kp_weight is None else np.asarray(self.kp_weight)[rows],
                        tpose=None if self.tpose is None else np.asarray(self.tpose)[rows])

    @property
    def holds_tpose(self) -> bool:
        """Whether any of these frames is held to the opening T-pose: only then has a frame the T-pose's rows (a
        window or search candidate after the T-pose carries none, rather than rows that are zero everywhere)."""
        return self.tpose is not None and bool(np.any(self.tpose))

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
    sigma_pelvis: float | None = None  # the hips joint's distance in front of the plane of the hip joints and the chest (None: off)
    pelvis_depth: float = -0.03  # around this (metres; negative: behind it), :func:`pelvis_depth`
    sigma_balance: float | None = None  # the hips farther across the floor than balance_band from the ankles' segment (None: off)
    balance_band: float = 0.2    # metres, :func:`balance_residual`
    sigma_hip: float | None = None  # on frames flagged ``away``: a thigh swung behind the pelvis's frontal plane by more than
    hip_back_cos: float = 0.6    # hip_back_cos (dot product with the pelvis's front) costs ((dot + hip_back_cos) / sigma_hip)² (None: off)
    contact_band: float = 0.03   # a planted ankle may rise this far above its standing height (heel and toe roll), metres
    sigma_offset: float = 0.03   # point offsets around their defaults, metres
    robust_scale: float = 2.0    # reprojection residuals beyond this many sigmas count as soft-L1 (outliers)
    sigma_sil: float = 4.0       # a joint or bone midpoint outside the actor's silhouette, pixels
    sil_tolerance: float = 2.0   # ... beyond this many pixels (the silhouette's edge is this uncertain)
    sigma_support: float = 0.05  # with a silhouette: the lower ankle above its standing height by more than
    support_band: float = 0.10   # this (metres) costs (excess / sigma_support)²: someone walking or turning stands on a foot
    sigma_away: float = 0.2      # with a silhouette, on frames flagged ``away``: the torso's front turned towards the
    #                              camera (cosine with the direction to it above -away_cos) costs ((cosine + away_cos) / sigma_away)²
    away_cos: float = 0.9        # (0.9: the front at least 154 degrees from the camera: measured on the 6 turning renders with
    #                              the true focal length, 0.5 (120 degrees, where the last front patch hides) left the torso side-on)
    sigma_bottom: float = 4.0    # with a silhouette: the floor below the lower ankle seen above the silhouette's lowest row
    bottom_tolerance: float = 8.0  # by more than this (pixels) costs (excess / sigma_bottom)², soft-L1 beyond robust_scale
    #                                (the toe, nearer the camera than the ankle, is lower in the image: 3-9 px on the renders)
    sigma_upright: float = 0.1   # with a silhouette, on frames flagged ``away``: the spine (hips -> neck) tilted from the
    upright_sin: float = 0.34    # vertical by more than asin(this) (20 degrees) costs ((sin(tilt) - this) / sigma_upright)²
    sigma_hang: float | None = None  # with a silhouette, on frames flagged ``away``: each limb bone's direction minus straight
    #                              down, over this (unit vectors), costs its square: the limbs' patches are unseen there and the
    #                              outline alone let them flail (None: off)
    sigma_kp: float = 4.0        # a detector's keypoint where the suit's point is lost, pixels (soft-L1 beyond robust_scale)
    sigma_tpose: float = 0.1     # on the opening T-pose's frames (TakeData.tpose): each limb bone's direction minus the T-pose's
    #                              (upper arms along the shoulder line, forearms and shins straight), unit vectors
    sigma_facing: float = 0.5    # with a facing hint (TakeData.facing): each front's unit vector minus the hint's, soft-L1 beyond robust_scale
    sigma_cover: float = 4.0     # with a silhouette: a sample of the outline farther from every projected bone than
    cover_tolerance: float = 0.06  # this fraction of the outline's height (about 0.1 m: the body's half thickness)
    #                                costs (excess px / sigma_cover)², soft-L1 beyond robust_scale (the model covers the outline)


def robust(r: np.ndarray, c: float) -> np.ndarray:
    """Residuals rescaled so their squares are the soft-L1 cost ``2 c² (√(1 + (r/c)²) − 1)`` (``≈ r²`` for small
    ``r``, linear beyond ``c``): the robust loss applied to reprojection only, not to the priors."""
    z = (r / c) ** 2
    return np.sign(r) * c * np.sqrt(2.0 * (np.sqrt(1.0 + z) - 1.0))


def robust_slope(r: np.ndarray, c: float) -> np.ndarray:
    """The derivative of :func:`robust` by ``r`` (1 at ``r = 0``, ``→ c / |r|`` far out), same shape as ``r``."""
    root = np.sqrt(1.0 + (r / c) ** 2)
    rho = c * np.sqrt(2.0 * (root - 1.0))
    small = np.abs(r) < 1e-6 * c
    return np.where(small, 1.0, np.abs(r) / np.where(small, 1.0, root * rho))


#: Points kept inside the actor's silhouette (:class:`SilhouetteField`): every joint centre, then every
#: bone's midpoint, as ``(a, b)`` joint pairs whose mean is the point (``a == b``: the joint itself).
SIL_PAIRS = np.array([(j, j) for j in range(N_JOINTS)] + [(int(PARENTS[j]), j) for j in range(1, N_JOINTS)])
#: Silhouette residuals per frame: the points of :data:`SIL_PAIRS`, the support (the lower ankle on the floor),
#: the thorax's and the pelvis's facing on frames where the actor is seen but no torso patch is, then the
#: silhouette's bottom reached (the floor below the lower ankle seen no higher than the silhouette's lowest row).
N_SIL = len(SIL_PAIRS) + 1 + 2 + 1
#: Samples of the outline per frame that the model must cover (:func:`cover_residuals`), evenly spaced along it.
N_COVER = 32
#: Bones (by child joint) drawn beyond their end for the cover term, metres: the skull above the head joint,
#: the hand beyond the wrist, the sole below the ankle.
COVER_EXTEND = {"head": 0.10, "left_wrist": 0.09, "right_wrist": 0.09, "left_ankle": 0.06, "right_ankle": 0.06}


def cover_segments(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cover term's segments as joint weights: ends ``A = a @ P`` and ``B = b @ P`` ``(15, 16)`` each (bone
    parent -> child, the bones of :data:`COVER_EXTEND` drawn beyond the child by that many metres of the bone
    lengths ``lengths`` ``(16,)``: linear in the joints, since the solver keeps every bone at its length)."""
    a = np.zeros((N_BONES, N_JOINTS))
    b = np.zeros((N_BONES, N_JOINTS))
    for j in range(1, N_JOINTS):
        e = COVER_EXTEND.get(list(JOINT_INDEX)[j], 0.0) / max(float(lengths[j]), 1e-6)
        a[j - 1, PARENTS[j]] = 1.0
        b[j - 1, j] += 1.0 + e
        b[j - 1, PARENTS[j]] -= e
    return a, b


def on_image_edge(q: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``(p,)`` bool: which points ``q`` ``(p, 2)`` (x, y pixels of an image of ``shape`` (rows, columns)) lie on its
    outermost pixels (within 1 px of the edge)."""
    h, w = shape
    return (q[:, 0] < 1.0) | (q[:, 0] > w - 2.0) | (q[:, 1] < 1.0) | (q[:, 1] > h - 2.0)


@dataclass
class SilhouetteField:
    """The actor's silhouette per frame as a distance-outside field (``segment.silhouette``): ``distance``
    ``(m, H', W')`` uint8 in pixels of the field (``scale`` x the frame's resolution; 0 inside the
    silhouette), ``index`` ``(n,)`` the field's row for each frame of the take (or window) being solved."""

    distance: np.ndarray
    scale: float
    index: np.ndarray
    #: ``(m,)`` the image row (full-resolution px, y down) of each field's lowest silhouette pixel, NaN if none
    bottom: np.ndarray | None = None

    #: shared by the subsets: the outline's samples of every field (:meth:`outline`), computed once
    cache: dict = field(default_factory=dict, repr=False)

    def subset(self, rows) -> "SilhouetteField":
        """The same field for the frames ``rows`` of this take (slice or index array)."""
        return SilhouetteField(self.distance, self.scale, np.asarray(self.index)[rows], self.bottom, self.cache)

    def outline(self, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """The outline on the frames ``rows``: :data:`N_COVER` points ``(k, N_COVER, 2)`` full-resolution px evenly
        spaced along the largest silhouette region's outer contour, and its height ``(k,)`` px (top to bottom
        row); NaN points and 0 height on a frame without a silhouette (an all-zero field: the actor not seen).

        Where the image's edge cuts the silhouette (the actor partly out of view) the contour runs along the edge:
        those samples are NaN (the body goes on beyond it, no edge of the body is there), and the height, which
        sets the cover term's tolerance, is at least that of the nearest frame whose silhouette is whole (a
        foot left in view is not a body 30 px tall)."""
        if "outline" not in self.cache:
            import cv2

            m = self.distance.shape[0]
            pts, height = np.full((m, N_COVER, 2), np.nan), np.zeros(m)
            cut = np.zeros(m, dtype=bool)  # frames whose silhouette the image's edge cuts
            for i in range(m):
                D = self.distance[i]
                if not D.any():
                    continue
                contours, _ = cv2.findContours((D == 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
                c = max(contours, key=cv2.contourArea)[:, 0].astype(np.float64)  # (p, 2) x, y of the field
                if len(c) < 3:
                    continue
                arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1))]
                at = (np.arange(N_COVER) + 0.5) * arc[-1] / N_COVER
                closed = np.vstack([c, c[:1]])
                pts[i] = np.stack([np.interp(at, arc, closed[:, 0]), np.interp(at, arc, closed[:, 1])], axis=1)
                height[i] = np.ptp(c[:, 1]) + 1.0
                cut[i] = on_image_edge(c, D.shape).any()
                pts[i, on_image_edge(pts[i], D.shape)] = np.nan
            whole = np.flatnonzero(~cut & (height > 0))
            cut_rows = np.flatnonzero(cut)
            if len(cut_rows) and len(whole):  # each cut frame's height at least its nearest whole frame's
                after = np.clip(np.searchsorted(whole, cut_rows), 1, len(whole) - 1) if len(whole) > 1 else np.zeros_like(cut_rows)
                before = np.maximum(after - 1, 0)
                nearest = np.where(cut_rows - whole[before] <= whole[after] - cut_rows, whole[before], whole[after])
                height[cut_rows] = np.maximum(height[cut_rows], height[nearest])
            self.cache["outline"] = ((pts + 0.5) / self.scale - 0.5, height / self.scale)
        pts, height = self.cache["outline"]
        idx = np.asarray(self.index)[rows]
        return pts[idx], height[idx]

    def seen(self, rows=slice(None)) -> np.ndarray:
        """``(k,)`` bool: whether the frames ``rows`` have a silhouette at all (an all-zero field: the actor not seen)."""
        D = np.asarray(self.distance)
        return D.reshape(D.shape[0], -1).any(axis=1)[np.asarray(self.index)[rows]]

    def bottom_rows(self, rows=slice(None)) -> np.ndarray:
        """``(k,)`` the silhouette's lowest row on the frames ``rows`` (NaN where unknown)."""
        idx = np.asarray(self.index)[rows]
        return np.full(idx.shape, np.nan) if self.bottom is None else np.asarray(self.bottom, dtype=np.float64)[idx]

    def sample(self, uv: np.ndarray, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """Distance outside the silhouette ``(k, p)`` full-resolution px at image points ``uv`` ``(k, p, 2)`` px
        on the frames ``rows`` (k of them), bilinear, and its gradient ``(k, p, 2)`` (px per px). Points
        beyond the image are not constrained (0, zero gradient): the image says nothing there (an actor
        partly out of view)."""
        D = self.distance
        h, w = D.shape[1:]
        idx = np.asarray(self.index)[rows][:, None]
        x = (uv[..., 0] + 0.5) * self.scale - 0.5
        y = (uv[..., 1] + 0.5) * self.scale - 0.5
        inx = (x > 0.0) & (x < w - 1)
        iny = (y > 0.0) & (y < h - 1)
        seen = (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
        x = np.clip(np.nan_to_num(x), 0.0, w - 1.000001)
        y = np.clip(np.nan_to_num(y), 0.0, h - 1.000001)
        x0 = np.minimum(x.astype(np.intp), w - 2)
        y0 = np.minimum(y.astype(np.intp), h - 2)
        fx, fy = x - x0, y - y0
        v00 = D[idx, y0, x0].astype(np.float64)
        v01 = D[idx, y0, x0 + 1].astype(np.float64)
        v10 = D[idx, y0 + 1, x0].astype(np.float64)
        v11 = D[idx, y0 + 1, x0 + 1].astype(np.float64)
        top = v00 + fx * (v01 - v00)
        bot = v10 + fx * (v11 - v10)
        val = (top + fy * (bot - top)) / self.scale * seen
        gx = ((v01 - v00) * (1.0 - fy) + (v11 - v10) * fy) * inx * seen  # field px per field px = full px per full px
        gy = (bot - top) * iny * seen
        return val, np.stack([gx, gy], axis=-1)


def bottom_residual(P: np.ndarray, f: float, centre: np.ndarray, nf: np.ndarray, dfl: float, sil: SilhouetteField,
                    w: "Weights", rows=slice(None)):
    """The silhouette's bottom reached ``(n,)``: the floor point below each ankle (``S = P_a - (n·P_a + d) n``)
    projected; the lower of the two in the image (row ``v``) should not be above the silhouette's lowest row
    ``b`` by more than ``bottom_tolerance``: ``robust(max(b - v - tol, 0) / sigma_bottom)`` (0 where ``b`` is
    unknown). Without it a body farther away and smaller (its head on the same pixel) fits inside the
    silhouette as well. Returns the residuals and the pieces of the Jacobian (the lower ankle ``k`` ``(n,)``,
    ``S`` ``(n, 3)`` its floor point, ``drho`` ``(n,)`` the soft-L1's derivative over ``sigma_bottom``)."""
    A = P[:, ANKLES]  # (n, 2, 3)
    S = A - (A @ nf + dfl)[..., None] * nf
    z = np.maximum(S[..., 2], 1e-3)
    v = f * S[..., 1] / z + centre[1]
    k = np.argmax(v, axis=1)
    n = P.shape[0]
    b = sil.bottom_rows(rows)
    e = np.where(np.isfinite(b), np.maximum(np.nan_to_num(b) - v[np.arange(n), k] - w.bottom_tolerance, 0.0), 0.0) / w.sigma_bottom
    r = robust(e, w.robust_scale)
    drho = np.where(e <= 0.0, 0.0, robust_slope(e, w.robust_scale))  # the clamp at 0 has no slope
    return r, {"k": k, "S": S[np.arange(n), k], "drho": drho / w.sigma_bottom}


def unseen_points(weight: np.ndarray) -> np.ndarray:
    """``(n, len(SIL_PAIRS))`` 1.0 for the silhouette's points not pinned by tracked points (weights ``(n, 16)``): a joint
    not tracked, a bone midpoint with an end not tracked. Where both are tracked the reprojection places them."""
    t = weight > 0
    return (~(t[:, SIL_PAIRS[:, 0]] & t[:, SIL_PAIRS[:, 1]])).astype(np.float64)


def sil_residuals(P: np.ndarray, f: float, centre: np.ndarray, sil: SilhouetteField, w: "Weights", rows=slice(None),
                  mask: np.ndarray | None = None):
    """Silhouette residuals ``(n, N_SIL)`` of joints ``P`` ``(n, 16, 3)`` camera frame at focal ``f``: each
    point of :data:`SIL_PAIRS`, projected, by how far it lies outside the silhouette beyond
    ``sil_tolerance`` px, over ``sigma_sil``, soft-L1 beyond ``robust_scale``, times ``mask`` ``(n, N)`` (the points
    :func:`unseen_points`; all when None); with the pieces the Jacobian
    needs (``drho`` ``(n, N_SIL)``, the field's gradient ``(n, N_SIL, 2)``, the points ``(n, N_SIL, 3)``)."""
    X = 0.5 * (P[:, SIL_PAIRS[:, 0]] + P[:, SIL_PAIRS[:, 1]])
    z = np.maximum(X[..., 2:3], 1e-3)
    uv = f * X[..., :2] / z + centre
    dist, grad = sil.sample(uv, rows)
    e = np.maximum(dist - w.sil_tolerance, 0.0) / w.sigma_sil
    if mask is not None:
        e = e * mask
    r = robust(e, w.robust_scale)
    drho = np.where(e <= 0.0, 0.0, robust_slope(e, w.robust_scale))  # the clamp at 0 has no slope
    return r, {"drho": drho, "grad": grad, "X": X}


def cover_residuals(P: np.ndarray, f: float, centre: np.ndarray, sil: SilhouetteField, lengths: np.ndarray, w: "Weights",
                    rows=slice(None), mask: np.ndarray | None = None):
    """The model covers the outline ``(n, N_COVER)``: each sample ``q`` of the outline (:meth:`SilhouetteField.outline`)
    by how far it lies from the nearest projected segment of :func:`cover_segments` (joints ``P`` ``(n, 16, 3)``
    camera frame, focal ``f``) beyond ``cover_tolerance`` of the outline's height, over ``sigma_cover``, soft-L1
    beyond ``robust_scale``, times ``mask`` ``(n,)`` (the frames where it applies; all when None; 0 on a frame without
    outline). The inside term alone lets a limb swing into depth
    inside the outline, or the torso turn side-on inside a back view's wider outline. Returns the residuals and
    the Jacobian's pieces: the nearest segment ``s`` ``(n, N_COVER)``, the position ``t`` along it, the unit
    vector ``g`` ``(n, N_COVER, 2)`` from the sample to its nearest point, ``drho`` (the soft-L1's slope over
    ``sigma_cover``), the segments' ends ``A, B`` ``(n, 15, 3)`` and their images ``ua, ub`` ``(n, 15, 2)``."""
    a, b = cover_segments(lengths)
    A, B = np.einsum("sj,njc->nsc", a, P), np.einsum("sj,njc->nsc", b, P)
    ua = f * A[..., :2] / np.maximum(A[..., 2:3], 1e-3) + centre
    ub = f * B[..., :2] / np.maximum(B[..., 2:3], 1e-3) + centre
    n = P.shape[0]
    r, drho, ts = np.zeros((n, N_COVER)), np.zeros((n, N_COVER)), np.zeros((n, N_COVER))
    s, g = np.zeros((n, N_COVER), dtype=np.intp), np.zeros((n, N_COVER, 2))
    on = np.arange(n) if mask is None else np.flatnonzero(mask)  # the nearest-segment search only where it applies
    if len(on):
        q, height = sil.outline(np.arange(len(np.asarray(sil.index)))[rows][on])
        ok = np.isfinite(q).all(axis=-1)  # (m, K)
        q = np.where(ok[..., None], q, 0.0)
        a_on = ua[on][:, None]  # (m, 1, S, 2)
        ab = ub[on][:, None] - a_on
        qa = q[:, :, None] - a_on  # (m, K, S, 2)
        t = np.clip(np.sum(qa * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-9), 0.0, 1.0)
        diff = a_on + t[..., None] * ab - q[:, :, None]  # nearest point minus sample
        dist = np.linalg.norm(diff, axis=-1)  # (m, K, S)
        s_on = np.argmin(dist, axis=-1)
        pick = lambda v: np.take_along_axis(v, s_on[..., None] if v.ndim == 3 else s_on[..., None, None], axis=2)[:, :, 0]  # noqa: E731
        d, s[on], ts[on] = pick(dist), s_on, pick(t)
        g[on] = pick(diff) / np.maximum(d, 1e-9)[..., None]
        e = np.where(ok, np.maximum(d - w.cover_tolerance * height[:, None], 0.0), 0.0) / w.sigma_cover
        if mask is not None:
            e = e * np.asarray(mask, dtype=np.float64)[on][:, None]
        r[on] = robust(e, w.robust_scale)
        drho[on] = np.where(e <= 0.0, 0.0, robust_slope(e, w.robust_scale)) / w.sigma_cover
    return r, {"s": s, "t": ts, "g": g, "drho": drho, "A": A, "B": B, "ua": ua, "ub": ub}


def upright_residual(P: np.ndarray, d: TakeData, w: "Weights"):
    """The spine upright on the frames ``d.away`` (only the head tracked) ``(n,)``: ``max(|h| - upright_sin, 0) /
    sigma_upright`` where ``h`` is the part of ``u = unit(P_neck - P_hips)`` across the vertical ``d.up`` (``|h|`` the
    sine of the spine's tilt); 0 elsewhere or without ``d.up``. With the actor's back to the camera the image
    fixes the torso's lean into depth weakly: the solved spines leaned 31 degrees (median, against 13 in the
    truth) on the back-turned frames of two turning renders. Returns the residuals and ``h`` ``(n, 3)``, ``|h|``
    ``(n,)``, the active mask ``(n,)``."""
    n = P.shape[0]
    u = unit(P[:, J["neck"]] - P[:, J["hips"]])
    up = np.zeros(3) if d.up is None else unit(np.asarray(d.up, dtype=np.float64))
    h = u - (u @ up)[:, None] * up
    s = np.sqrt(np.einsum("ni,ni->n", h, h))
    on = (np.zeros(n, bool) if d.away is None or d.up is None else np.asarray(d.away, bool)) & (s > w.upright_sin)
    return np.where(on, s - w.upright_sin, 0.0) / w.sigma_upright, {"h": h, "s": s, "on": on, "up": up}


def balance_residual(P: np.ndarray, d: TakeData, w: "Weights") -> tuple[np.ndarray, dict]:
    """The hips over the feet ``(..., n)``: ``max(dist - balance_band, 0) / sigma_balance``, ``dist`` the distance
    across the floor (perpendicular to ``d.up``) from the hips joint to the segment between the two ankles; 0 without
    ``sigma_balance`` or ``d.up``. Someone standing, walking, turning or hopping keeps the hips within about 0.2 m
    of that segment (the renders' CMU takes: p95 76-161 mm, at most 208), while the image fixes the body's lean
    into depth weakly: the solves had the hips up to 0.3-0.5 m off it on the turning renders, where their errors
    were largest. Returns the residuals and, for the Jacobian, ``s`` (where along the segment the nearest point
    lies, 0 at the left ankle) and ``u`` (the unit direction from that point to the hips, camera frame) ``(..., n[, 3])``
    and the active mask."""
    shape = P.shape[:-2]
    if w.sigma_balance is None or d.up is None:  # off: every value the Jacobian reads, all zero
        return np.zeros(shape), {"s": np.zeros(shape), "u": np.zeros(shape + (3,)), "on": np.zeros(shape, bool)}
    up = unit(np.asarray(d.up, dtype=np.float64))
    a, b, h = P[..., J["left_ankle"], :], P[..., J["right_ankle"], :], P[..., J["hips"], :]
    E, H = b - a, h - a
    E = E - (E @ up)[..., None] * up
    H = H - (H @ up)[..., None] * up
    s = np.clip(np.sum(H * E, axis=-1) / np.maximum(np.sum(E * E, axis=-1), 1e-12), 0.0, 1.0)
    D = H - s[..., None] * E
    dist = np.linalg.norm(D, axis=-1)
    on = dist > w.balance_band
    return (np.where(on, dist - w.balance_band, 0.0) / w.sigma_balance,
            {"s": s, "u": D / np.maximum(dist, 1e-12)[..., None], "on": on})


#: The thighs ``(hip joint, knee)`` of the hip's extension limit (:func:`hip_extension_residual`)
THIGHS = ((J["left_hip"], J["left_knee"]), (J["right_hip"], J["right_knee"]))


def hip_extension_residual(P: np.ndarray, pelvis: np.ndarray, w: "Weights", away: np.ndarray) -> np.ndarray:
    """Each thigh swung behind the body ``(..., n, 2)`` on the frames ``away`` ``(n,)`` bool (only the head tracked,
    :attr:`TakeData.away`): ``min(unit(knee - hip joint) . pelvis + hip_back_cos, 0) / sigma_hip``,
    ``pelvis`` the pelvis's front ``(..., n, 3)`` (:func:`fronts`), joints ``P`` ``(..., n, 16, 3)``.
    A hip extends about 20-30 degrees behind the frontal plane; the renders' CMU takes keep the dot product above
    -0.27 on every frame (walks, a hop, a kick). The image does not: a knee raised in front of someone who faces
    away from the camera projects where a thigh swung as far behind them would, and the limbs' hang prior of such
    frames prefers the lower, wrong one. Only there: on every frame the limit moved the sixteen renders' turning
    takes by up to 26 mm either way (docs/solver-log.md round 31)."""
    on = np.asarray(away, dtype=bool)
    u = unit(np.stack([P[..., k, :] - P[..., h, :] for h, k in THIGHS], axis=-2))
    return np.minimum(np.sum(u * pelvis[..., None, :], axis=-1) + w.hip_back_cos, 0.0) * (on / w.sigma_hip)[:, None]


#: Limb bones (by child joint) the hang prior (:func:`hang_residual`) pulls towards straight down.
HANG_BONES = np.array([J[n] for n in ("left_elbow", "left_wrist", "right_elbow", "right_wrist",
                                      "left_knee", "left_ankle", "right_knee", "right_ankle")])
N_HANG = 3 * len(HANG_BONES)


def hang_residual(P: np.ndarray, d: TakeData, w: "Weights") -> tuple[np.ndarray, np.ndarray]:
    """The limbs hanging on the frames ``d.away`` (only the head tracked) ``(n, N_HANG)``: ``(unit(P_b - P_parent)
    + up) / sigma_hang`` for each bone of :data:`HANG_BONES` (0 elsewhere, without ``d.up`` or ``sigma_hang``): with
    the actor's back to the camera no limb patch is seen and the outline alone does not place the limbs. Returns the
    residuals and the active mask ``(n,)``."""
    n = P.shape[0]
    on = np.zeros(n, bool) if (d.away is None or d.up is None or w.sigma_hang is None) else np.asarray(d.away, bool)
    if not on.any():
        return np.zeros((n, N_HANG)), on
    up = unit(np.asarray(d.up, dtype=np.float64))
    u = unit(P[:, HANG_BONES] - P[:, PARENTS[HANG_BONES]])
    return ((u + up) * (on / w.sigma_hang)[:, None, None]).reshape(n, N_HANG), on


def facing_residual(thorax: np.ndarray, pelvis: np.ndarray, d: TakeData, w: "Weights") -> np.ndarray:
    """The torso facing as a detector's own 3D shows it ``(..., n, 6)``: ``robust((front - hint) / sigma_facing)``
    for the thorax's and the pelvis's fronts ``(..., n, 3)`` (camera frame) against ``d.facing`` (0 where the hint
    is a zero vector). A single camera leaves a torso turned towards it and the mirror turn away from it almost
    equally cheap where few torso points are seen; a detector trained on people knows which way they face."""
    hint = np.asarray(d.facing, dtype=np.float64)
    on = (np.linalg.norm(hint, axis=-1) > 0.5)[..., None]  # (n, 2, 1)
    r = np.concatenate([(thorax - hint[:, 0]) * on[:, 0], (pelvis - hint[:, 1]) * on[:, 1]], axis=-1)
    return robust(r / w.sigma_facing, w.robust_scale)


#: The opening T-pose's limbs as joint quadruples ``(a, b, c, d)``: bone a -> b points as c -> d does (the upper
#: arms along the shoulder line, outwards; the forearms on from the upper arms; the shins on from the thighs).
#: The thighs are left free: held along the spine they lean with it, and the image fixes the spine's lean into
#: depth weakly, so the planted feet moved and the floor with them (on the sample's exact patch centres the camera
#: came out 8.8 cm too high instead of 2.8)
TPOSE_PAIRS = np.array([[J[a], J[b], J[c], J[d]] for a, b, c, d in (
    ("left_shoulder", "left_elbow", "right_shoulder", "left_shoulder"), ("left_elbow", "left_wrist", "left_shoulder", "left_elbow"),
    ("right_shoulder", "right_elbow", "left_shoulder", "right_shoulder"), ("right_elbow", "right_wrist", "right_shoulder", "right_elbow"),
    ("left_knee", "left_ankle", "left_hip", "left_knee"), ("right_knee", "right_ankle", "right_hip", "right_knee"))])
#: T-pose residuals per frame: x, y, z of each of :data:`TPOSE_PAIRS`
N_TPOSE = 3 * len(TPOSE_PAIRS)


def tpose_residual(P: np.ndarray, d: TakeData, w: "Weights") -> np.ndarray:
    """The limbs in the opening T-pose ``(..., n, N_TPOSE)``: ``(unit(P_b - P_a) - unit(P_d - P_c)) / sigma_tpose``
    for each of :data:`TPOSE_PAIRS` on the frames ``d.tpose`` (0 elsewhere); joints ``P`` ``(..., n, 16, 3)``.
    The image of an arm held out sideways barely changes as it swings 20-30 degrees into depth (131_01's left arm
    was solved 30 degrees towards the camera, the truth's 11 degrees away), and the depth side chosen there is
    carried on after the T-pose; the take is required to open with a T-pose, so there the pose is known."""
    on = np.asarray(d.tpose, dtype=np.float64) / w.sigma_tpose
    a, b, c, e = (TPOSE_PAIRS[:, i] for i in range(4))
    r = unit(P[..., b, :] - P[..., a, :]) - unit(P[..., e, :] - P[..., c, :])
    return (r * on[:, None, None]).reshape(P.shape[:-2] + (N_TPOSE,))


#: Left/right joint pairs whose detector keypoints may come swapped (:func:`keypoint_residual` takes the cheaper)
KP_PAIRS = np.array([(J["left_" + n], J["right_" + n]) for n in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")])
#: Keypoint residuals per frame: u, v of every joint
N_KP = 2 * N_JOINTS


def keypoint_targets(uv: np.ndarray, d: TakeData) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's detector keypoint ``(..., n, 16, 2)`` px and its weight ``(..., n, 16)`` given the model's
    projected joints ``uv`` ``(..., n, 16, 2)``: per left/right pair (:data:`KP_PAIRS`) the assignment (as
    labelled or swapped) that costs less; a joint's weight is 0 where the suit's own point is tracked
    (``d.weight > 0``) and the keypoint's confidence elsewhere."""
    kp = np.asarray(d.keypoints, dtype=np.float64)
    cw = np.asarray(d.kp_weight, dtype=np.float64)
    lost = (np.asarray(d.weight) <= 0).astype(np.float64)
    a, b = KP_PAIRS[:, 0], KP_PAIRS[:, 1]
    ua, ub = uv[..., a, :], uv[..., b, :]
    same = lost[:, a] * cw[:, a] * np.sum((ua - kp[:, a]) ** 2, axis=-1) + lost[:, b] * cw[:, b] * np.sum((ub - kp[:, b]) ** 2, axis=-1)
    swap = lost[:, a] * cw[:, b] * np.sum((ua - kp[:, b]) ** 2, axis=-1) + lost[:, b] * cw[:, a] * np.sum((ub - kp[:, a]) ** 2, axis=-1)
    s = swap < same  # (..., n, 6)
    target = np.broadcast_to(kp, uv.shape).copy()
    wt = np.broadcast_to(cw, uv.shape[:-1]).copy()
    target[..., a, :] = np.where(s[..., None], kp[:, b], kp[:, a])
    target[..., b, :] = np.where(s[..., None], kp[:, a], kp[:, b])
    wt[..., a] = np.where(s, cw[:, b], cw[:, a])
    wt[..., b] = np.where(s, cw[:, a], cw[:, b])
    return target, wt * lost


def keypoint_residual(P: np.ndarray, f: float, d: TakeData, w: "Weights") -> np.ndarray:
    """A detector's keypoints where the suit's points are lost ``(..., n, N_KP)``: each joint centre of ``P``
    ``(..., n, 16, 3)`` (camera frame) projected at focal ``f``, minus its keypoint (:func:`keypoint_targets`:
    left and right as labelled or swapped, whichever fits), times its weight, over ``sigma_kp``, soft-L1 beyond
    ``robust_scale``. With the actor's back to the camera no patch is seen, but a detector still finds the
    limbs (about 4 px from the truth on the turning renders when its left/right labels are taken either way)."""
    z = np.maximum(P[..., 2:3], 1e-3)
    uv = f * P[..., :2] / z + d.centre
    target, wt = keypoint_targets(uv, d)
    return robust((uv - target) * (wt[..., None] / w.sigma_kp), w.robust_scale).reshape(P.shape[:-2] + (N_KP,))


def seat_on_outline(P: np.ndarray, f: float, centre: np.ndarray, nf: np.ndarray, dfl: float, sil: SilhouetteField,
                    frames: np.ndarray, lift_px: float = -1.0, scales: np.ndarray = np.geomspace(0.6, 1.8, 241)) -> np.ndarray:
    """A start for the frames where the image says little of the body: joints ``P`` ``(n, 16, 3)`` (camera frame)
    with each frame of the mask ``frames`` ``(n,)`` moved, unchanged, along its root's viewing ray (``P + (s - 1)
    P_root``, the root's pixel kept) to the depth where the floor below its lower ankle (the lower in the image)
    is seen ``lift_px`` above the silhouette's lowest row (-1: 1 px below it, the median over the 6 turning
    renders' back-turned frames of ``bench/labelling.py``, quartiles -7 and +2 px: seen from behind, the nearer
    foot is the trailing one, its heel lifting), the factor ``s`` the best of ``scales``, median-filtered over 5
    frames; frames where that row is unknown stay. With the actor's back to the camera only the head is tracked
    and the whole-take solve, started from the last pose seen, kept the body near where it turned (131_01: 1.2 m
    short of its walk away); floor ``nf·X + dfl = 0``, focal ``f`` px."""
    from scipy.ndimage import median_filter

    b = sil.bottom_rows()
    use = np.asarray(frames, bool) & np.isfinite(b)
    if not use.any():
        return P
    A = P[use][:, None, ANKLES] + (scales[None, :, None, None] - 1.0) * P[use][:, None, None, 0]  # (k, s, 2, 3)
    S = A - (A @ nf + dfl)[..., None] * nf
    v = (f * S[..., 1] / np.maximum(S[..., 2], 1e-3) + centre[1]).max(axis=-1)  # (k, s) the lower floor point's row
    best = np.ones(P.shape[0])
    best[use] = scales[np.argmin(np.abs(v - (b[use, None] - lift_px)), axis=1)]
    best = np.where(use, median_filter(best, size=5, mode="nearest"), 1.0)
    return P + (best - 1.0)[:, None, None] * P[:, None, 0]


def frame_blocks(d: TakeData, w: "Weights") -> dict[str, slice]:
    """Where each kind of per-frame residual sits in a frame's block of :meth:`TakeProblem.frame_terms`, in order:
    the terms every take has, the pelvis's and the balance prior's rows with ``w.sigma_pelvis`` / ``w.sigma_balance``
    (``w``: the problem's :class:`Weights`), the silhouette's four with a silhouette, then the keypoints, the facing
    hint and the opening T-pose, each only with its data (a term that is off has no rows). One layout for the residuals' costs
    (:meth:`TakeProblem.term_costs`) and their Jacobian (:func:`.take_jacobian.residual_jacobian`)."""
    has_sil = d.silhouette is not None
    sizes = [("reprojection", N_JOINTS * 2), ("torso", len(TORSO_PAIRS)), ("hinge", len(HINGES)), ("below_floor", 2),
             ("contact", 2), ("pose", 6), ("pelvis", 0 if w.sigma_pelvis is None else 1),
             ("balance", 0 if w.sigma_balance is None else 1), ("hip_extension", 0 if w.sigma_hip is None or d.away is None else len(THIGHS)),
             ("silhouette", N_SIL if has_sil else 0), ("cover", N_COVER if has_sil else 0),
             ("upright", 1 if has_sil else 0), ("hang", N_HANG if has_sil else 0)]
    sizes += [(nm, k) for nm, k, on in (("keypoints", N_KP, d.keypoints is not None), ("facing", N_FACING, d.facing is not None),
                                         ("tpose", N_TPOSE, d.holds_tpose)) if on]
    out, row = {}, 0
    for nm, k in sizes:
        out[nm] = slice(row, row + k)
        row += k
    return out


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
#: facing where the thorax faces, 3); with ``sigma_pelvis`` the hips' fold (:func:`pelvis_depth`) 1 more, with
#: ``sigma_balance`` the hips over the feet (:func:`balance_residual`) 1 more, with ``sigma_hip`` and frames that can be flagged
#: away the thighs' extension limit (:func:`hip_extension_residual`) 2 more; with a silhouette, :data:`N_SIL` + :data:`N_COVER` + 1 + :data:`N_HANG` more,
#: with a facing hint :data:`N_FACING` more, on a take with an opening T-pose :data:`N_TPOSE` more
#: (:attr:`TakeProblem.n_frame_res`).
N_FRAME_RES = N_JOINTS * 2 + len(TORSO_PAIRS) + len(HINGES) + 4 + 6
#: With a facing hint (:attr:`TakeData.facing`), the residuals of a frame before the T-pose's: the thorax's and the
#: pelvis's fronts against the hint's (:func:`facing_residual`)
N_FACING = 6


class TakeProblem:
    """Residuals of one take (or window); their Jacobian is :mod:`.take_jacobian`'s, the solve :mod:`.take_solver`'s.

    ``x`` = globals (``n_glob`` values; none when ``fixed_globals`` is given) then ``n`` frames of
    :data:`PER_FRAME` values. Bone directions are tangent updates around ``ref`` ``(n, 15, 3)`` and the floor
    normal around ``n_ref`` ``(3,)``; :meth:`recentre` moves both references to the current solution.

    Residual vector: per-frame block ``(n, n_frame_res)`` (frame-major; :data:`N_FRAME_RES`, plus the silhouette's
    :data:`N_SIL`, the cover's :data:`N_COVER`, the upright spine's 1 and the hanging limbs' :data:`N_HANG` at its
    end when the data has a silhouette, then a detector's keypoints :data:`N_KP`, torso facing :data:`N_FACING` and
    the opening T-pose's limbs :data:`N_TPOSE` when the data has them), then accelerations
    ``(n - 2, 16 * 3)``, planted-ankle slides ``(n, 2)``, then global priors (point offsets, a known focal).
    """

    def __init__(self, data: TakeData, ref: np.ndarray, n_ref: np.ndarray, weights: Weights,
                 offsets0: np.ndarray, fixed_globals: np.ndarray | None = None, free_offsets: bool = True,
                 focal_prior: tuple[float, float] | None = None, free_lengths: bool = False,
                 floor_prior: tuple[np.ndarray, float] | None = None):
        self.d, self.w = data, weights
        self.n = data.points.shape[0]
        self.offsets0 = offsets0
        self.layout = Layout(self.n, free_offsets, free_lengths)
        self.fixed_globals = None if fixed_globals is None else np.asarray(fixed_globals, dtype=np.float64)
        self.focal_prior = focal_prior  # (focal px, sigma of log f): a known focal length held (nearly) fixed
        # (up (3,) camera frame, sigma radians): the floor's normal as the room's lines show it
        self.floor_prior = None if floor_prior is None else (unit(np.asarray(floor_prior[0], dtype=np.float64)), float(floor_prior[1]))
        self.n_glob = 0 if fixed_globals is not None else self.layout.n_globals
        self.blocks = frame_blocks(data, weights)
        self.n_frame_res = next(reversed(self.blocks.values())).stop
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
        """Joint positions ``(..., n, 16, 3)`` camera frame from frame unknowns ``(..., n, PER_FRAME)`` (any
        leading axes) and bone lengths ``L`` (the body's when not given)."""
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
        """Per-frame residuals ``(..., n, n_frame_res)`` of joints ``P`` ``(..., n, 16, 3)`` under globals ``g``
        (any leading axes broadcast against the take's data; the silhouette's term takes ``(n, 16, 3)`` only)."""
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
        terms = [rep, torso, np.stack(hin, axis=-1), below, on, head, twist]
        if w.sigma_pelvis is not None:  # the optional priors have their own rows only when on
            terms.append(((pelvis_depth(P) - w.pelvis_depth) / w.sigma_pelvis)[..., None])
        if w.sigma_balance is not None:
            terms.append(balance_residual(P, d, w)[0][..., None])
        if w.sigma_hip is not None and d.away is not None:  # rows only where frames can be flagged away (a silhouette)
            terms.append(hip_extension_residual(P, pelvis, w, d.away))
        if d.silhouette is not None:  # the silhouette's points, and the support: with them the feet's image rows fix the depth
            away = np.zeros(P.shape[0], bool) if d.away is None else np.asarray(d.away, dtype=bool)
            to_cam = [-unit(P[..., J["chest"], :]), -unit(P[..., J["hips"], :])]
            facing = [np.where(away, np.maximum(np.sum(fr * c, axis=-1) + w.away_cos, 0.0), 0.0) / w.sigma_away
                      for fr, c in zip((thorax, pelvis), to_cam)]
            terms += [sil_residuals(P, f, d.centre, d.silhouette, w, mask=unseen_points(d.weight))[0],
                      np.maximum(h.min(axis=-1, keepdims=True) - w.support_band, 0.0) / w.sigma_support,
                      np.stack(facing, axis=-1), bottom_residual(P, f, d.centre, nf, dfl, d.silhouette, w)[0][:, None],
                      cover_residuals(P, f, d.centre, d.silhouette, d.lengths, w, mask=torso_unseen(d.weight))[0],
                      upright_residual(P, d, w)[0][:, None], hang_residual(P, d, w)[0]]
        if d.keypoints is not None:  # a detector's keypoints where the suit's points are lost
            terms.append(keypoint_residual(P, f, d, w))
        if d.facing is not None:  # the fronts against the detector's
            terms.append(facing_residual(thorax, pelvis, d, w))
        if d.holds_tpose:  # the last block: the opening T-pose's limbs
            terms.append(tpose_residual(P, d, w))
        return np.concatenate(terms, axis=-1)

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
            if self.floor_prior is not None:
                out.append((self.floor(g)[0] - self.floor_prior[0]) / self.floor_prior[1])
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
        out = {nm: 0.5 * float(np.sum(F[:, rows] ** 2)) for nm, rows in self.blocks.items()}
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
