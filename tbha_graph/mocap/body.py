"""The ``body`` port: the actor's bone lengths, reading them, and the T-pose on the floor they give.

A :class:`Body` is ``{bone: metres}``, one entry per bone, the bone named by its child joint (as
:data:`tbha_graph.mocap.skeleton.DEFAULT_BONE_LENGTHS`); a missing bone uses the default length. Stored as
that JSON mapping. :func:`body_lengths` turns a body into the ``(16,)`` array the solvers use and
:func:`lengths_to_body` back; :func:`tpose_on_floor` is the rest pose the calibrators and the 3D
solvers start from (metres, calibration world frame).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
from pydantic import RootModel, model_validator

from ..core.errors import NodeError, did_you_mean
from .skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, bone_lengths_array, tpose

#: Height above the floor of the ankle joint centre in the rest pose, metres (adult, shoes off).
DEFAULT_ANKLE_HEIGHT = 0.08

#: Bone names (child joints), in joint order.
BONE_NAMES: tuple[str, ...] = JOINT_NAMES[1:]


def check_bone_names(names, where: str) -> None:
    """Raise :class:`NodeError` for the first name that is not a bone (child joint) name, with did-you-mean."""
    for name in names:
        if name not in BONE_NAMES:
            raise NodeError(
                f"{where}: unknown bone {name!r}{did_you_mean(name, BONE_NAMES)}",
                hint=f"bones are named by their child joint, one of: {', '.join(BONE_NAMES)}",
            )


def _check_lengths(body: Mapping, where: str) -> None:
    check_bone_names(body, where)
    for name, value in body.items():
        # float(): a huge YAML integer (10**40) is a Python int numpy cannot take, 10**400 no float at all
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(float(value) if abs(value) < 1e300 else np.inf) or value <= 0:
            raise NodeError(f"{where}: bone {name!r} has length {value!r}", hint="give a positive length in metres")


class Body(RootModel[dict[str, float]]):
    """Bone lengths ``{bone: metres}`` (see the module docstring); every name a bone, every length
    positive and finite."""

    @model_validator(mode="before")
    @classmethod
    def _check(cls, data):
        if isinstance(data, Mapping):
            try:
                _check_lengths(data, "body")
            except NodeError as e:
                raise ValueError(e.message) from None
        return data

    # read like the mapping it is: body["left_knee"], set(body), dict(body)
    def __getitem__(self, bone: str) -> float:
        return self.root[bone]

    def __iter__(self):
        return iter(self.root)

    def __len__(self) -> int:
        return len(self.root)

    def keys(self):
        return self.root.keys()

    def items(self):
        return self.root.items()

    def get(self, bone: str, default: float | None = None) -> float | None:
        return self.root.get(bone, default)

    def lengths(self) -> np.ndarray:
        """Bone lengths ``(N_JOINTS,)`` metres (entry ``j`` = |joint j - parent|, root 0), defaults for missing bones."""
        return bone_lengths_array(self.root)


def body_lengths(body: Body | Mapping[str, float] | None, where: str = "body") -> np.ndarray:
    """Bone lengths ``(N_JOINTS,)`` metres (entry ``j`` = |joint j - parent|, root 0) from a body.

    ``None`` gives :data:`DEFAULT_BONE_LENGTHS`; missing bones also fall back to them.
    Raises :class:`NodeError` naming ``where`` for unknown names or non-positive / non-numeric lengths.
    """
    if isinstance(body, Body):
        return body.lengths()
    body = dict(body or {})
    _check_lengths(body, where)
    return bone_lengths_array(body)


def lengths_to_body(lengths: np.ndarray) -> dict[str, float]:
    """Inverse of :func:`body_lengths`: ``(N_JOINTS,)`` metres -> ``{bone: metres}`` for all 15 bones."""
    lengths = np.asarray(lengths, dtype=np.float64).reshape(N_JOINTS)
    return {name: float(lengths[JOINT_INDEX[name]]) for name in BONE_NAMES}


def hips_height(lengths: np.ndarray, ankle_height: float = DEFAULT_ANKLE_HEIGHT) -> float:
    """Height of the hips (root) joint above the floor in the rest T-pose, metres: the vertical drop from
    the hips to the lower ankle (hip offset, thigh, shank) plus ``ankle_height``."""
    rest = tpose(lengths, root=(0.0, 0.0, 0.0))
    ankles = rest[[JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 1]
    return float(-ankles.min() + ankle_height)


def tpose_on_floor(lengths: np.ndarray, ankle_height: float = DEFAULT_ANKLE_HEIGHT) -> np.ndarray:
    """The rest T-pose ``(N_JOINTS, 3)`` metres in the calibration world frame.

    World origin: on the floor (y = 0) straight below the hips joint; the body lies in the plane z = 0
    (its coronal plane), x = actor's left, y up, facing +z. The hips sit at ``hips_height`` so the
    ankle joint centres are ``ankle_height`` above the floor.
    """
    lengths = np.asarray(lengths, dtype=np.float64)
    return tpose(lengths, root=(0.0, hips_height(lengths, ankle_height), 0.0))


#: Height of the crown of the head above the head joint (the skull base), metres, adult.
CROWN_ABOVE_HEAD_JOINT = 0.18


def default_stature(lengths: np.ndarray | None = None, ankle_height: float = DEFAULT_ANKLE_HEIGHT) -> float:
    """Approximate standing height, metres, of a body: floor to the head joint (skull base) in the rest
    pose plus :data:`CROWN_ABOVE_HEAD_JOINT`."""
    lengths = bone_lengths_array() if lengths is None else np.asarray(lengths, dtype=np.float64)
    rest = tpose_on_floor(lengths, ankle_height)
    return float(rest[JOINT_INDEX["head"], 1] + CROWN_ABOVE_HEAD_JOINT)


#: Standing height of the default body (the reference for scaling defaults to a user's height), metres.
DEFAULT_STATURE = default_stature()
