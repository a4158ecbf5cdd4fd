"""``viz.skeleton_sheet``: a contact sheet of a motion's stick figures, to see at once whether the
character stands upright (y up) and faces the right way (+z), before opening the BVH anywhere.

Columns: ``frames`` evenly spaced frames of the clip. Rows, both orthographic, y up:

* front view, seen from +z looking towards -z: world +x (the actor's left) to the right, so an actor
  facing +z faces the viewer with the left side on the viewer's right;
* side view, seen from the actor's right (-x) looking towards +x: world +z to the right, so an actor
  facing +z faces right. A grey arrow from the chest shows the facing direction in both views.

Left limbs blue, right limbs red, spine and head dark grey. Each column is centred on the frame's root
(hips) horizontally; all panels share one scale and the vertical range, with the floor (lowest joint of
the clip) drawn as a line. Each column title gives the frame, its time, the lean of the spine from +y and
the heading (facing direction in the ground plane, degrees from +z, positive towards +x).
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..ports import IMAGE, MOTION
from ..skeleton import BONES, JOINT_INDEX, N_JOINTS
from . import style
from ...core.figure import new_figure, save_png

_L_SH, _R_SH = JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]
_L_HIP, _R_HIP = JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]
_HIPS, _CHEST, _NECK, _HEAD = (JOINT_INDEX[n] for n in ("hips", "chest", "neck", "head"))


class SheetParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    frames: int = Field(8, ge=1, le=24, description="number of frames shown, evenly spaced over the clip")
    title: str = Field("", description="title above the sheet (default: the overall lean and heading)")
    dpi: int = Field(100, ge=50, le=300, description="resolution of the PNG", json_schema_extra={"unit": "dots/inch"})


def posture(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame posture of ``joints`` ``(n, 16, 3)`` metres (world, y up): lean ``(n,)`` degrees of the
    hips->neck direction from +y; heading ``(n,)`` degrees of the facing direction in the ground plane
    from +z (positive towards +x); facing ``(n, 3)`` unit vector (left x up, left = shoulders and hips
    left minus right; NaN when undefined)."""
    j = np.asarray(joints, dtype=np.float64)
    spine = j[:, _NECK] - j[:, _HIPS]
    with np.errstate(invalid="ignore", divide="ignore"):
        lean = np.degrees(np.arccos(np.clip(spine[:, 1] / np.linalg.norm(spine, axis=-1), -1.0, 1.0)))
        left = (j[:, _L_SH] - j[:, _R_SH]) + (j[:, _L_HIP] - j[:, _R_HIP])
        facing = np.cross(left, np.array([0.0, 1.0, 0.0]))
        facing /= np.linalg.norm(facing, axis=-1, keepdims=True)
    heading = np.degrees(np.arctan2(facing[:, 0], facing[:, 2]))
    return lean, heading, facing


def _draw_row(ax, figures: list[np.ndarray], arrows: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Stick figures ``(16, 2)`` (horizontal, vertical) metres, already placed side by side, on one
    axes; ``arrows``: (start, end) of each figure's facing arrow (skipped when not finite)."""
    from matplotlib.collections import LineCollection

    segments, colors, heads = [], [], []
    for p2 in figures:
        ok = np.isfinite(p2).all(-1)
        for a, b in BONES:
            if ok[a] and ok[b]:
                segments.append(p2[[a, b]])
                colors.append(style.rgb(style.side_color(int(b))))
        ax.scatter(p2[ok, 0], p2[ok, 1], s=6, color="black", zorder=3)
        if ok[_HEAD]:
            heads.append(p2[_HEAD])
    ax.add_collection(LineCollection(segments, colors=colors, linewidths=2.0, capstyle="round"))
    if heads:
        h = np.array(heads)
        ax.scatter(h[:, 0], h[:, 1], s=90, facecolors="none", edgecolors=style.rgb(style.CENTRE_BGR), zorder=3)
    for start, end in arrows:
        if np.isfinite(start).all() and np.isfinite(end).all():
            ax.annotate("", xy=tuple(end), xytext=tuple(start), arrowprops={"arrowstyle": "-|>", "color": "0.45", "lw": 1.5})


def plot_sheet(joints: np.ndarray, fps: float, path, n_shown: int = 8, title: str = "", dpi: int = 100):
    """Draw the contact sheet (see module docstring) of ``joints`` ``(n, 16, 3)`` metres to ``path``.

    One axes per view; the frames are placed side by side in it, each centred on its root, so all
    figures share one scale (metres on the vertical axis)."""
    j = np.asarray(joints, dtype=np.float64)
    n = j.shape[0]
    idx = np.unique(np.rint(np.linspace(0, n - 1, min(n_shown, n))).astype(int))
    lean, heading, facing = posture(j)
    sel = j[idx]
    root = sel[:, _HIPS]
    views = (("front (from +z)\ny (m)", 0), ("side (from the actor's right, -x)\ny (m)", 2))  # horizontal axis: +x, +z
    rel = np.concatenate([np.abs(sel[..., 0] - root[:, None, 0]), np.abs(sel[..., 2] - root[:, None, 2])], axis=1)
    floor, top = float(np.nanmin(j[..., 1])), float(np.nanmax(j[..., 1]))
    half = max((float(np.nanmax(rel)) if np.isfinite(rel).any() else 0.0) + 0.15, 0.3 * (top - floor))
    cols = len(idx)
    width_m, height_m = 2 * half * cols, top - floor + 0.6  # the row's extent in metres
    scale = 1.6 / (2 * half)  # inches per metre: 1.6 in per figure
    fig_w, fig_h = 0.8 + width_m * scale + 0.2, 2 * height_m * scale + 1.3
    fig = new_figure(fig_w, fig_h, constrained=False)
    fig.subplots_adjust(left=0.8 / fig_w, right=1 - 0.2 / fig_w, bottom=0.1 / fig_h, top=1 - 0.7 / fig_h, hspace=0.5 / (height_m * scale))
    axes = fig.subplots(2, 1)
    for ax, (label, axis) in zip(axes, views):
        figures, arrows = [], []
        for c, f in enumerate(idx):
            centre = (2 * c + 1) * half
            shift = centre - root[c, axis]
            figures.append(np.stack([sel[c, :, axis] + shift, sel[c, :, 1]], axis=1))
            start = np.array([sel[c, _CHEST, axis] + shift, sel[c, _CHEST, 1]])
            arrows.append((start, start + 0.3 * np.array([facing[f, axis], facing[f, 1]])))
        _draw_row(ax, figures, arrows)
        ax.axhline(floor, color="0.6", lw=1.0)
        for c in range(1, cols):
            ax.axvline(2 * c * half, color="0.85", lw=0.8)
        ax.set_xlim(0.0, width_m)
        ax.set_ylim(floor - 0.1, top + 0.5)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
    for c, f in enumerate(idx):
        axes[0].text((2 * c + 1) * half, top + 0.45, f"frame {f} ({f / fps:.2f} s)\nlean {lean[f]:.0f}°, heading {heading[f]:+.0f}°",
                     ha="center", va="top", fontsize=7)
    verdict = (f"spine lean from +y: median {np.nanmedian(lean):.0f}° — heading from +z: median {np.nanmedian(heading):+.0f}°"
               if np.isfinite(lean).any() else "posture undefined (non-finite joints)")
    fig.suptitle(title or f"Skeleton contact sheet, y up — {verdict}\nleft side blue, right side red, grey arrow = facing",
                 fontsize=9, y=1 - 0.08 / fig_h, va="top")
    return save_png(fig, path, dpi)


@node("viz.skeleton_sheet", version=1, inputs={"motion": MOTION}, outputs={"png": IMAGE},
      params=SheetParams)
def skeleton_sheet(ctx, motion):
    """A PNG contact sheet of ~8 frames of the motion as stick figures, front and side views (y up):
    shows at a glance whether the character stands upright and faces +z."""
    p: SheetParams = ctx.params
    joints = np.asarray(motion["joints"], dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (N_JOINTS, 3) or joints.shape[0] == 0:
        raise NodeError(f"motion: joints has shape {joints.shape}, expected (n_frames > 0, {N_JOINTS}, 3)")
    if not np.isfinite(joints).any():
        raise NodeError("motion: no joint position is finite (all NaN/inf)", hint="check the reconstruction upstream")
    fps = float(np.asarray(motion["fps"]))
    return {"png": plot_sheet(joints, fps if fps > 0 else 1.0, ctx.output_path("skeleton_sheet.png"), p.frames, p.title, p.dpi)}
