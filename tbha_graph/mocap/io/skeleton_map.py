"""Mapping a source BVH skeleton onto the 16 TBHA joints (:data:`tbha_graph.mocap.skeleton.JOINT_NAMES`).

A mapping is a small YAML file::

    description: CMU mocap database, Hahne BVH conversion
    units_to_metres: 0.05644     # metres per file unit
    axes: x y z                  # world axes in source axes, e.g. "x z -y" for a z-up source
    joints:                      # TBHA joint: source joint (all 16 required)
      hips: Hips
      chest: Chest2
      ...

``axes`` gives, for world x, y, z in turn, the source axis (with an optional sign) it equals; the world
is y up with the actor facing +z in its rest pose (left = +x). Bundled mappings live in
``tbha_graph/mocap/io/mappings/`` and are named by their file stem (``"cmu"``); any other value is a path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator

from ...core.errors import Location, NodeError, did_you_mean
from ..skeleton import JOINT_NAMES
from .bvh import Bvh, bvh_positions, read_bvh

MAPPINGS_DIR = Path(__file__).with_name("mappings")


class MappingError(NodeError):
    """A skeleton mapping file that is invalid or does not fit the BVH it is applied to."""


def bundled_mappings() -> list[str]:
    """Names of the mappings shipped with the package (``["cmu", ...]``)."""
    return sorted(p.stem for p in MAPPINGS_DIR.glob("*.yaml"))


class SkeletonMapping(BaseModel):
    """A validated mapping: ``joints`` TBHA joint -> source joint, ``units_to_metres``, ``axes``."""

    model_config = ConfigDict(extra="forbid")

    description: str = Field("", description="what skeleton this maps")
    units_to_metres: float = Field(gt=0, description="metres per source file unit", json_schema_extra={"unit": "m"})
    axes: str = Field("x y z", description="source axis for world x, y, z, e.g. 'x z -y' for a z-up source")
    joints: dict[str, str] = Field(description="TBHA joint name -> source joint name, all 16")
    #: the file it was loaded from and the line of each key (for error messages)
    _source: str = PrivateAttr("<mapping>")
    _lines: dict[str, int] = PrivateAttr(default_factory=dict)

    @field_validator("joints")
    @classmethod
    def _all_sixteen(cls, v: dict[str, str]) -> dict[str, str]:
        unknown = [k for k in v if k not in JOINT_NAMES]
        if unknown:
            raise ValueError(
                "; ".join(f"unknown TBHA joint {k!r}{did_you_mean(k, JOINT_NAMES)}" for k in unknown)
                + f" (the 16 joints are: {', '.join(JOINT_NAMES)})"
            )
        missing = [k for k in JOINT_NAMES if k not in v]
        if missing:
            raise ValueError(f"no source joint given for {missing}: all 16 TBHA joints must be mapped")
        return {k: str(s) for k, s in v.items()}

    @field_validator("axes")
    @classmethod
    def _axes(cls, v: str) -> str:
        axes_matrix(v)
        return v

    def world_from_source(self) -> np.ndarray:
        """(3, 3) signed permutation matrix ``M`` with ``world = M @ source``."""
        return axes_matrix(self.axes)


def axes_matrix(spec: str) -> np.ndarray:
    """Parse ``"x z -y"`` into a (3, 3) signed permutation matrix (rows: world x, y, z); right-handed only."""
    words = spec.replace(",", " ").split()
    m = np.zeros((3, 3))
    if len(words) == 3:
        for row, w in enumerate(words):
            sign = -1.0 if w.startswith("-") else 1.0
            axis = w.lstrip("+-").lower()
            if axis in ("x", "y", "z"):
                m[row, "xyz".index(axis)] = sign
    if not (np.abs(m).sum(axis=0) == 1).all() or not (np.abs(m).sum(axis=1) == 1).all():
        raise ValueError(f"axes {spec!r} must name each source axis x, y, z once, with optional signs, e.g. 'x z -y'")
    if np.linalg.det(m) < 0:
        raise ValueError(f"axes {spec!r} is a mirror (left-handed); flip the sign of one axis")
    return m


def _key_lines(text: str) -> dict[str, int]:
    """1-based line of each key under ``joints:`` (for error messages); empty when it cannot tell."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return {}
    out: dict[str, int] = {}
    if isinstance(root, yaml.MappingNode):
        for k, v in root.value:
            out[str(k.value)] = k.start_mark.line + 1
            if k.value == "joints" and isinstance(v, yaml.MappingNode):
                out.update({f"joints.{jk.value}": jk.start_mark.line + 1 for jk, _ in v.value})
    return out


def resolve_mapping_path(name_or_path: str | Path) -> Path:
    """A bundled mapping name (``"cmu"``) or a path to a YAML file -> the file's path."""
    s = str(name_or_path)
    if s in bundled_mappings():
        return MAPPINGS_DIR / f"{s}.yaml"
    path = Path(s).expanduser()
    if not path.is_file():
        raise MappingError(
            f"no skeleton mapping {s!r}{did_you_mean(s, bundled_mappings())}",
            hint=f"give a bundled mapping ({', '.join(bundled_mappings())}) or the path of a mapping YAML file",
        )
    return path


def load_mapping(name_or_path: str | Path) -> SkeletonMapping:
    """Load and validate a mapping: a bundled name (``"cmu"``) or a YAML file path.

    Raises :class:`MappingError` naming the file (and line, when known) and what is wrong.
    """
    from ...core.yamlfile import read_data_file

    path = resolve_mapping_path(name_or_path)
    data = read_data_file(path, "skeleton mapping", MappingError)  # safe loading; bad bytes, syntax errors, duplicate keys with their line
    text = path.read_text(encoding="utf-8")
    if not isinstance(data, dict):
        raise MappingError("a mapping file must be a YAML mapping with 'units_to_metres' and 'joints'",
                           location=Location(str(path)))
    try:
        mapping = SkeletonMapping.model_validate(data)
    except ValidationError as e:
        lines = _key_lines(text)
        err = e.errors()[0]
        field = ".".join(str(p) for p in err["loc"])
        msg = str(err["msg"]).removeprefix("Value error, ")
        raise MappingError(f"{field}: {msg}", location=Location(str(path), lines.get(field.split(".")[0], 0))) from None
    mapping._source = str(path)
    mapping._lines = _key_lines(text)
    return mapping


def joint_indices(bvh: Bvh, mapping: SkeletonMapping, bvh_name: str = "the BVH file") -> np.ndarray:
    """Index in ``bvh.joints`` of the source joint of each TBHA joint, shape (16,) int.

    Raises :class:`MappingError` naming the mapping file and line and suggesting close BVH joint names.
    """
    names = bvh.names
    source, lines = mapping._source, mapping._lines
    idx = []
    for ours in JOINT_NAMES:
        theirs = mapping.joints[ours]
        if theirs not in names:
            raise MappingError(
                f"'{ours}: {theirs}': there is no joint '{theirs}' in {bvh_name}{did_you_mean(theirs, names)}",
                location=Location(source, lines.get(f"joints.{ours}", 0)),
                hint=f"its joints are: {', '.join(names)}",
            )
        idx.append(names.index(theirs))
    return np.array(idx, dtype=np.int64)


def map_positions(bvh: Bvh, mapping: SkeletonMapping, units_to_metres: float | None = None,
                  bvh_name: str = "the BVH file") -> np.ndarray:
    """TBHA joint positions ``(n_frames, 16, 3)`` metres, world frame (y up), from an in-memory BVH."""
    idx = joint_indices(bvh, mapping, bvh_name)
    scale = mapping.units_to_metres if units_to_metres is None else float(units_to_metres)
    pos = bvh_positions(bvh)[:, idx] * scale
    return pos @ mapping.world_from_source().T


def motion16_from_bvh(path: str | Path, mapping: str | Path = "cmu",
                      units_to_metres: float | None = None) -> dict[str, np.ndarray]:
    """Read a BVH file and map it onto the 16 TBHA joints.

    Returns ``{"joints": (n_frames, 16, 3) metres world, "fps": () float, "joint_names": (16,) str}``
    (the keys of the ``MOTION`` port). ``units_to_metres`` overrides the mapping's value.
    """
    if units_to_metres is not None and not units_to_metres > 0:
        raise MappingError(f"units_to_metres must be > 0, got {units_to_metres}")
    m = load_mapping(mapping)
    bvh = read_bvh(path)
    joints = map_positions(bvh, m, units_to_metres, bvh_name=str(path))
    return {
        "joints": joints,
        "fps": np.asarray(bvh.fps, dtype=np.float64),
        "joint_names": np.array(JOINT_NAMES),
    }


#: Rest T-pose direction of the End Site of each leaf joint (head up, hands along the arms, feet forward).
_TPOSE_END_DIRS = {
    "head": (0.0, 1.0, 0.0),
    "left_wrist": (1.0, 0.0, 0.0),
    "right_wrist": (-1.0, 0.0, 0.0),
    "left_ankle": (0.0, 0.0, 1.0),
    "right_ankle": (0.0, 0.0, 1.0),
}


def _end_vector(bvh: Bvh, src: int, rest: np.ndarray) -> np.ndarray:
    """Rest vector (file units) from source joint ``src`` to the End Site reached by following first children."""
    parents = bvh.parents
    j = src
    while bvh.joints[j].end_site is None:
        kids = np.flatnonzero(parents == j)
        if kids.size == 0:
            return np.zeros(3)
        j = int(kids[0])
    return rest[j] + bvh.joints[j].end_site - rest[src]


def rotations16_from_bvh(path: str | Path, mapping: str | Path = "cmu",
                         units_to_metres: float | None = None) -> dict[str, np.ndarray]:
    """Joint rotations of the 16-joint model derived from a BVH file (a ``ROTATIONS`` bundle, metres).

    Each TBHA joint takes the world rotation of its mapped source joint, re-expressed so that identity
    is the TBHA rest T-pose (arms along +-x, legs down, spine up; branching joints are best-fit aligned):
    ``offsets[c] = B[p] @ rest_vector[c]``, ``world[j] = world_src[j] @ B[j]^-1``. Limb joints reproduce
    the source positions exactly; joints past a rotating source joint that the 16-joint model lacks
    (the spine's lowerback/Chest, the lowerneck) differ by the bend of that joint. Returns
    ``local_quat`` (n, 16, 4) xyzw, ``root_position`` (n, 3), ``offsets`` (16, 3), ``end_offsets``
    (16, 3), ``fps`` ().
    """
    from scipy.spatial.transform import Rotation

    from ..kinematics import forward_kinematics
    from ..quat import quat_inv, quat_mul
    from ..skeleton import CHILDREN, PARENTS, TPOSE_DIRECTIONS
    from .bvh import bvh_to_local

    m = load_mapping(mapping)
    bvh = read_bvh(path)
    idx = joint_indices(bvh, m, str(path))
    scale = (m.units_to_metres if units_to_metres is None else float(units_to_metres))
    axes = Rotation.from_matrix(m.world_from_source())
    local_src, root_src = bvh_to_local(bvh)
    n, nj = bvh.n_frames, len(bvh.joints)
    rest = forward_kinematics(bvh.parents, bvh.offsets, np.tile([0.0, 0.0, 0.0, 1.0], (1, nj, 1)), np.zeros((1, 3)))[0][0]
    _, world_src = forward_kinematics(bvh.parents, bvh.offsets, local_src, root_src)
    rest_w = axes.apply(rest[idx]) * scale  # (16, 3) metres, world axes
    world = (axes * Rotation.from_quat(world_src[:, idx].reshape(-1, 4)) * axes.inv()).as_quat().reshape(n, 16, 4)

    offsets = np.zeros((16, 3))
    end_offsets = np.zeros((16, 3))
    b_quat = np.tile([0.0, 0.0, 0.0, 1.0], (16, 1))
    for j in range(16):
        kids = CHILDREN[j]
        if kids:
            vec = rest_w[list(kids)] - rest_w[j]
            target = TPOSE_DIRECTIONS[list(kids)] * np.linalg.norm(vec, axis=1, keepdims=True)
        else:
            vec = axes.apply(_end_vector(bvh, int(idx[j]), rest))[None] * scale
            target = np.array([_TPOSE_END_DIRS[JOINT_NAMES[j]]]) * np.linalg.norm(vec)
        if np.linalg.norm(vec) > 0:
            b = Rotation.align_vectors(target, vec)[0]
            b_quat[j] = b.as_quat()
            if not kids:
                end_offsets[j] = b.apply(vec[0])
        for c in kids:
            offsets[c] = Rotation.from_quat(b_quat[j]).apply(rest_w[c] - rest_w[j])
    world = quat_mul(world, quat_inv(b_quat))
    parent_world = world[:, np.maximum(PARENTS, 0)]
    local = quat_mul(quat_inv(parent_world), world)
    local[:, 0] = world[:, 0]
    root_position = axes.apply(root_src) * scale
    return {
        "local_quat": local,
        "root_position": root_position,
        "offsets": offsets,
        "end_offsets": end_offsets,
        "fps": np.asarray(bvh.fps, dtype=np.float64),
    }
