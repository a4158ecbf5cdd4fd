"""The suit spec: which colour each patch has. Shared by the renderer and the segmenters.

A suit spec is a small YAML file::

    colors:            # name -> sRGB hex
      red: "#e02020"
      ...
    patches:           # patched joint -> colour name (every joint but the head)
      left_shoulder: red
      ...
    patch_radius: 0.045   # metres, radius of each circular patch on the suit surface

Same-coloured patches are told apart by posture rules on the first frame (seed 000): the default suit
pairs each upper-limb joint with the lower-limb joint of the same side, and the neck with the hips.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, Field, field_validator, model_validator

from .skeleton import PATCHED_JOINTS

DEFAULT_SUIT_PATH = Path(__file__).with_name("suit_default.yaml")


class SuitSpec(BaseModel):
    """Colours of the suit's patches. ``colors`` are sRGB hex strings, ``patches`` map joint -> colour."""

    colors: dict[str, str] = Field(description="colour name -> sRGB hex '#rrggbb'")
    patches: dict[str, str] = Field(description="patched joint name -> colour name")
    patch_radius: float = Field(0.045, gt=0, description="patch radius on the suit surface, metres")
    suit_color: str = Field("#f2f2f2", description="colour of the suit itself, sRGB hex")

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
        return self

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
    from ..core.yamlfile import load_yaml

    path = DEFAULT_SUIT_PATH if path is None else Path(path)
    if not path.is_file():
        raise NodeError(f"suit spec {path} does not exist", hint="give the path of a suit YAML; see tbha_graph/mocap/suit_default.yaml")
    data, problems = load_yaml(path)  # safe loading; reports bad bytes, syntax errors and duplicate keys with their line
    if problems:
        raise NodeError(f"suit spec {path} is not valid: {problems[0].message}", location=problems[0].location,
                        hint=problems[0].hint) from None
    try:
        return SuitSpec.model_validate(data)
    except Exception as e:
        raise NodeError(f"suit spec {path}: {e}", hint="fix the file; joint and colour names are listed above") from None
