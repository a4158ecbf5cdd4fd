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
    path = resolve_mapping_path(name_or_path)
    text = path.read_text(encoding="utf-8")
    try:
        data = yaml.safe_load(text)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark
        raise MappingError(f"YAML syntax error: {e.problem}",
                           location=Location(str(path), mark.line + 1 if mark else 0)) from None
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
