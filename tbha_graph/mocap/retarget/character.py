"""A user's character skeleton read from a BVH file and matched to the 16 TBHA joints by a mapping.

Only the ``HIERARCHY`` matters: joint names, parents, ``OFFSET`` s (the rest pose: every rotation zero,
which need not be a T-pose) and End Sites; the file's motion frames are ignored. The mapping is a
skeleton-mapping YAML (:mod:`tbha_graph.mocap.io.skeleton_map`: TBHA joint -> character joint,
``units_to_metres``, ``axes``), e.g. the bundled ``mixamo`` or ``cmu``. Everything here is in world
axes (y up, the character facing +z, left = +x) and metres; the file's own axes and units are kept to
write the result back the same way.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core.errors import Location, NodeError
from ..io.bvh import Bvh, read_bvh
from ..io.skeleton_map import MappingError, SkeletonMapping, joint_indices, load_mapping
from ..kinematics import forward_kinematics
from ..skeleton import JOINT_NAMES, PARENTS

#: Euler order used for a character joint without three rotation channels in its file.
DEFAULT_ORDER = "ZXY"


@dataclass
class Character:
    """A character skeleton in world axes and metres.

    ``parents`` (J,) with the root first; ``offsets`` (J, 3) rest offsets from the parent; ``ends``
    (J, 3) End Site offsets (zero where ``end_mask`` is False); ``rest`` (J, 3) rest positions with the
    root at the origin; ``mapped`` (16,) index of each TBHA joint's character joint; ``orders``: each
    joint's Euler order in the file (``DEFAULT_ORDER`` when it has fewer than 3 rotation channels).
    """

    path: Path
    mapping: SkeletonMapping
    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    ends: np.ndarray
    end_mask: list[bool]
    rest: np.ndarray
    mapped: np.ndarray
    orders: list[str]
    units_to_metres: float

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def ancestors(self, j: int) -> list[int]:
        """Indices of the proper ancestors of joint ``j``, nearest first."""
        out = []
        p = int(self.parents[j])
        while p >= 0:
            out.append(p)
            p = int(self.parents[p])
        return out

    def path_between(self, top: int, bottom: int) -> list[int]:
        """Joints strictly between ancestor ``top`` and ``bottom``, top-down (empty when adjacent)."""
        chain = []
        p = int(self.parents[bottom])
        while p != top:
            chain.append(p)
            p = int(self.parents[p])
        return chain[::-1]


def _orders(bvh: Bvh) -> list[str]:
    out = []
    for j in bvh.joints:
        rot = "".join(c[0] for c in j.channels if c.endswith("rotation"))
        out.append(rot if len(rot) == 3 else DEFAULT_ORDER)
    return out


def load_character(path: str | Path, mapping: str | Path, units_to_metres: float | None = None) -> Character:
    """Read a character BVH and match it to the 16 TBHA joints with ``mapping`` (bundled name or path).

    Raises :class:`NodeError` (naming the file, the mapping line and the joints) when a mapped joint is
    missing, two TBHA joints share a character joint, the mapping contradicts the character's hierarchy
    (e.g. ``left_elbow`` not below ``left_shoulder``), or a mapped bone has zero rest length.
    """
    path = Path(path)
    m = load_mapping(mapping)
    bvh = read_bvh(path)
    idx = joint_indices(bvh, m, str(path))
    src, lines = m._source, m._lines
    names = bvh.names
    seen: dict[int, str] = {}
    for ours, t in zip(JOINT_NAMES, idx):
        if int(t) in seen:
            raise MappingError(
                f"'{seen[int(t)]}' and '{ours}' are both mapped to joint '{names[t]}' of {path.name}",
                location=Location(src, lines.get(f"joints.{ours}", 0)),
                hint="each of the 16 joints needs its own character joint",
            )
        seen[int(t)] = ours
    scale = m.units_to_metres if units_to_metres is None else float(units_to_metres)
    w = m.world_from_source()
    offsets = bvh.offsets @ w.T * scale
    end_mask = [j.end_site is not None for j in bvh.joints]
    ends = np.array([(j.end_site if j.end_site is not None else np.zeros(3)) for j in bvh.joints]) @ w.T * scale
    parents = bvh.parents
    nj = len(names)
    rest = forward_kinematics(parents, offsets, np.tile([0.0, 0.0, 0.0, 1.0], (1, nj, 1)), np.zeros((1, 3)))[0][0]
    char = Character(path, m, names, parents, offsets, ends, end_mask, rest, idx, _orders(bvh), scale)
    for j in range(1, len(JOINT_NAMES)):
        p = int(PARENTS[j])
        tj, tp = int(idx[j]), int(idx[p])
        if tp not in char.ancestors(tj):
            raise MappingError(
                f"'{JOINT_NAMES[j]}: {names[tj]}' is not below '{JOINT_NAMES[p]}: {names[tp]}' in {path.name}, "
                f"but {JOINT_NAMES[j]} is a child of {JOINT_NAMES[p]}",
                location=Location(src, lines.get(f"joints.{JOINT_NAMES[j]}", 0)),
                hint="map each joint to a character joint below the one its parent is mapped to",
            )
        if np.linalg.norm(rest[tj] - rest[tp]) < 1e-6:
            raise NodeError(
                f"{path.name}: joints '{names[tp]}' ({JOINT_NAMES[p]}) and '{names[tj]}' ({JOINT_NAMES[j]}) "
                "are at the same rest position, so the bone between them has no direction",
                hint="map the TBHA joint to a character joint that is a real bone length away",
            )
    return char
