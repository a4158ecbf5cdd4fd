"""The suit spec: which colour each patch has. Shared by the renderer and the segmenters.

A suit spec is a small YAML file::

    colors:            # name -> sRGB hex
      red: "#e02020"
      ...
    patches:           # patched joint -> colour name (every joint but the head)
      left_shoulder: red
      ...
    patch_radius: 0.045   # metres, radius of each circular patch on the suit surface
    sharing: upper_lower  # optional: which patches may share a colour (see below)

Patches given the same colour share it. Same-coloured patches are told apart by posture rules on the
first frame (seed 000), then by continuity and the body's facing; the trackers can do that for two
kinds of pairs only (:data:`SHARING_PAIRS`):

* ``upper_lower`` (the default suit): an upper-limb joint with the lower-limb joint of the same side
  (shoulder/hip, elbow/knee, wrist/ankle), and the neck with the hips;
* ``left_right`` (the seed's suit, ``suit_seed.yaml``): a left joint with its right mirror, and the
  neck with the hips.

``sharing`` declares the kind (``none``: no colour shared; ``mixed``: pairs of both kinds; unset: any
pair of either kind). At most two patches share a colour. Any other sharing (three patches, a joint
with its own parent, the chest with anything...) is an ambiguity the trackers cannot resolve:
:func:`load_suit` refuses it naming the file and the line of the offending patch.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, Field, field_validator, model_validator

from .skeleton import PATCHED_JOINTS

DEFAULT_SUIT_PATH = Path(__file__).with_name("suit_default.yaml")
#: The bundled seed-style suit: left and right limbs share a colour.
SEED_SUIT_PATH = Path(__file__).with_name("suit_seed.yaml")

_LIMBS = (("shoulder", "hip"), ("elbow", "knee"), ("wrist", "ankle"))
#: Pairs of patches that may share a colour, by sharing kind (unordered pairs of joint names).
SHARING_PAIRS: dict[str, frozenset[frozenset[str]]] = {
    "upper_lower": frozenset(
        [frozenset((f"{s}_{u}", f"{s}_{lo}")) for s in ("left", "right") for u, lo in _LIMBS] + [frozenset(("neck", "hips"))]
    ),
    "left_right": frozenset(
        [frozenset((f"left_{j}", f"right_{j}")) for pair in _LIMBS for j in pair] + [frozenset(("neck", "hips"))]
    ),
}
SHARING_PAIRS["mixed"] = SHARING_PAIRS["upper_lower"] | SHARING_PAIRS["left_right"]
SHARING_PAIRS["none"] = frozenset()


class SharingError(ValueError):
    """Patches share a colour in a way the trackers cannot resolve; ``joints`` names the patches involved."""

    def __init__(self, message: str, joints: list[str]):
        super().__init__(message)
        self.joints = list(joints)


def sharing_kind(groups: list[list[str]]) -> str:
    """The kind of a suit's same-coloured groups (lists of joint names): ``none``, ``upper_lower``,
    ``left_right`` or ``mixed`` (neck/hips counts as either)."""
    pairs = [frozenset(g) for g in groups if len(g) == 2]
    if not pairs:
        return "none"
    for kind in ("upper_lower", "left_right", "mixed"):
        if all(p in SHARING_PAIRS[kind] for p in pairs):
            return kind
    return "invalid"


class SuitSpec(BaseModel):
    """Colours of the suit's patches. ``colors`` are sRGB hex strings, ``patches`` map joint -> colour."""

    colors: dict[str, str] = Field(description="colour name -> sRGB hex '#rrggbb'")
    patches: dict[str, str] = Field(description="patched joint name -> colour name")
    patch_radius: float = Field(0.045, gt=0, description="patch radius on the suit surface, metres")
    suit_color: str = Field("#f2f2f2", description="colour of the suit itself, sRGB hex")
    sharing: Literal["none", "upper_lower", "left_right", "mixed"] | None = Field(
        None, description="which patches may share a colour: 'upper_lower' (default suit), 'left_right' (seed suit), "
                          "'mixed' (pairs of both kinds), 'none'; unset = any pair of either kind",
    )

    @field_validator("colors")
    @classmethod
    def _hex(cls, v: dict[str, str]) -> dict[str, str]:
        for name, hx in v.items():
            s = str(hx).lstrip("#")
            if len(s) != 6 or any(c not in "0123456789abcdefABCDEF" for c in s):
                raise ValueError(f"colour {name!r}: {hx!r} is not an sRGB hex string like '#e02020'")
        return v

    @model_validator(mode="after")
    def _joints_and_colours(self) -> "SuitSpec":
        unknown = [j for j in self.patches if j not in PATCHED_JOINTS]
        if unknown:
            from ..core.errors import did_you_mean

            raise ValueError(
                "; ".join(f"unknown joint {j!r}{did_you_mean(j, PATCHED_JOINTS)}" for j in unknown)
                + f" (patched joints are: {', '.join(PATCHED_JOINTS)})"
            )
        bad = {j: c for j, c in self.patches.items() if c not in self.colors}
        if bad:
            from ..core.errors import did_you_mean

            raise ValueError(
                "; ".join(f"joint {j!r} uses unknown colour {c!r}{did_you_mean(c, self.colors)}" for j, c in bad.items())
                + f" (colours defined: {', '.join(self.colors)})"
            )
        missing = [j for j in PATCHED_JOINTS if j not in self.patches]
        if missing:
            raise ValueError(f"no colour for joint(s) {missing}: every joint but the head needs a patch")
        self.check_sharing()
        return self

    def check_sharing(self) -> None:
        """Raise :class:`SharingError` for colour sharing the trackers cannot resolve (module docstring)."""
        allowed = SHARING_PAIRS[self.sharing or "mixed"]
        declared = f"'sharing: {self.sharing}'" if self.sharing else "either kind"
        for colour, joints in self.joints_by_colour().items():
            if len(joints) > 2:
                raise SharingError(
                    f"colour {colour!r} is worn by {len(joints)} patches ({', '.join(joints)}): at most two patches may "
                    "share a colour, or the trackers cannot tell them apart", joints)
            if len(joints) == 2 and frozenset(joints) not in allowed:
                kinds = [k for k in ("upper_lower", "left_right") if frozenset(joints) in SHARING_PAIRS[k]]
                why = (f"that is a {kinds[0]} pair but the suit declares {declared}" if kinds else
                       "the trackers can only tell apart an upper/lower limb pair of one side (e.g. left_elbow/left_knee), "
                       "a left/right mirror pair (e.g. left_elbow/right_elbow) or neck/hips")
                raise SharingError(f"patches {joints[0]} and {joints[1]} share colour {colour!r}: {why}", joints)

    @property
    def sharing_kind(self) -> str:
        """The kind of sharing the suit actually has (see :func:`sharing_kind`)."""
        return sharing_kind(list(self.joints_by_colour().values()))

    def rgb(self, colour: str) -> np.ndarray:
        """sRGB of a colour name as floats in [0, 1], shape (3,) in R, G, B order."""
        s = self.colors[colour].lstrip("#")
        return np.array([int(s[i : i + 2], 16) for i in (0, 2, 4)], dtype=np.float64) / 255.0

    def patch_rgb(self) -> np.ndarray:
        """Patch colours per patched joint (order of PATCHED_JOINTS), shape (15, 3) RGB in [0, 1]."""
        return np.stack([self.rgb(self.patches[j]) for j in PATCHED_JOINTS])

    def joints_by_colour(self) -> dict[str, list[str]]:
        out: dict[str, list[str]] = {c: [] for c in self.colors}
        for j in PATCHED_JOINTS:
            out[self.patches[j]].append(j)
        return {c: js for c, js in out.items() if js}


def load_suit(path: str | Path | None = None) -> SuitSpec:
    """Read a suit spec YAML (safe loading). ``None`` gives the default suit.

    Raises :class:`tbha_graph.core.errors.NodeError` naming the file and the problem.
    """
    from ..core.errors import NodeError
    from ..core.yamlfile import read_data_file

    path = DEFAULT_SUIT_PATH if path is None else Path(path)
    if not path.is_file():
        raise NodeError(f"suit spec {path} does not exist", hint="give the path of a suit YAML; see tbha_graph/mocap/suit_default.yaml")
    data = read_data_file(path, "suit spec", NodeError)  # safe loading; bad bytes, syntax errors, duplicate keys with their line
    try:
        return SuitSpec.model_validate(data)
    except Exception as e:
        sharing = _sharing_error(e)
        if sharing is not None:
            patches = data.get("patches") if isinstance(data, dict) else None
            locs = [patches.loc_of(j) for j in sharing.joints] if hasattr(patches, "loc_of") else []
            loc = max(locs, key=lambda lc: lc.line) if locs else None  # the patch written last
            raise NodeError(f"suit spec {path}: {sharing}", location=loc,
                            hint="give these patches different colours, or change 'sharing' to the kind the suit uses "
                                 "(upper_lower, left_right, mixed)") from None
        raise NodeError(f"suit spec {path}: {e}", hint="fix the file; joint and colour names are listed above") from None


def _sharing_error(e: Exception) -> SharingError | None:
    """The :class:`SharingError` behind a pydantic ValidationError, if that is what it is."""
    if isinstance(e, SharingError):
        return e
    for err in getattr(e, "errors", lambda: [])():
        cause = (err.get("ctx") or {}).get("error")
        if isinstance(cause, SharingError):
            return cause
    return None
