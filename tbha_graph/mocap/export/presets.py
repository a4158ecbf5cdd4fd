"""Export presets: how a BVH is laid out for the application that imports it, and the checks every
export runs on its own file.

The capture's world frame is metres, y up, the actor facing +z in the rest pose (left = +x). A preset
says which file axes, units, Euler order and joint names to write, and models what the importing
application does with the file, so the export can verify that the character will stand upright and face
the right way there. Chosen by one param ``preset`` on ``export.bvh`` and ``retarget.bvh_character``:

=========  ===========================  =====  ========  ==========  ===========================================
preset     file axes                    units  Euler     names       in the application (after its import)
=========  ===========================  =====  ========  ==========  ===========================================
blender    y up, actor faces +z         m      XYZ       as given    Blender defaults (Forward -Z, Up Y): z up,
                                                                     the actor faces -Y (the Front view sees its
                                                                     face), like Rigify and Mixamo characters
y-up       y up, actor faces +z         cm     ZXY       as given    Maya, MotionBuilder, Unity (and most game
                                                                     engines): y up, faces +z
mixamo     y up, actor faces +z         cm     ZXY       mixamorig:  Mixamo / Unreal / Unity humanoid
                                                                     retargeters: y up, faces +z, T-pose rest
=========  ===========================  =====  ========  ==========  ===========================================

Import settings, per preset (see :data:`PRESETS` ``import_settings``):

* ``blender``: *File > Import > Motion Capture (.bvh)* with its defaults: Forward ``-Z``, Up ``Y``,
  Scale ``1.0``, Rotation ``Native``, Start Frame 1 (``bpy.ops.import_anim.bvh(axis_forward='-Z',
  axis_up='Y')``). Blender maps file (x, y, z) to Blender (x, -z, y) and bakes it into the armature.
  The file stays y up: writing it z up would make Blender's default import lay the actor on its back.
  With Rotation ``Native`` each bone takes the file's channel order as its Euler mode: XYZ channels
  give Blender's default ``XYZ`` mode (checked with bpy 5.0.1).
* ``y-up``: Maya *File > Import* (BVH via MotionBuilder or an importer plug-in), MotionBuilder
  *File > Motion File Import*, Unity BVH importers: no axis change, scale 1 (centimetres, the unit of
  Maya, MotionBuilder and FBX). Unity is left-handed; its BVH importers mirror x on import, so the
  actor still faces +z there. Euler ZXY, the MotionBuilder / CMU BVH order.
* ``mixamo``: the 16 joints get Mixamo rig names (``tbha_graph/mocap/io/mappings/mixamo.yaml``:
  ``mixamorig:Hips``, ``mixamorig:Spine2``, ``mixamorig:LeftArm`` ...), rest T-pose, centimetres, y up,
  facing +z: what auto-mapping retargeters (Blender add-ons, Unreal IK Retargeter, Unity Humanoid)
  recognise. For a full Mixamo rig (extra spine, clavicle, finger joints) retarget with
  ``retarget.bvh_character`` and mapping ``mixamo`` instead. The retargeter keeps the user's character's
  names and rest pose whatever the preset (that is the rig it drives); presets there set axes, units and
  Euler order.

Self-checks, run after writing every file (a failure raises :class:`NodeError`, never a warning):

1. :func:`readback_error`: the file read back with the project's reader (:func:`..io.bvh.read_bvh`),
   forward kinematics of every frame mapped back to world metres with the preset's declared axes,
   must put every checked joint (and End Site) within ``tolerance_m`` (0.1 mm for every preset) of
   where the writer's input puts it. The axes conversion of the motion (:func:`to_file_axes`) and the
   check (:meth:`Preset.world_from_file` on positions) are separate code paths, so a wrong axis in
   the conversion is caught.
2. :func:`orientation_error`: the file's rest pose, seen in the application's axes (``app_axes``),
   must have the head above the hips along the application's up axis (within 30 degrees) and face
   the application's forward (within 45 degrees). This catches a preset whose file axes do not suit
   its application (the "imports lying down / turned round" complaint).

:func:`contact_sheet` draws a few frames of the file, as the application will show them, front and
side views (a matplotlib PNG), so a user sees at a glance that the character stands upright and
faces the right way.
"""
from __future__ import annotations

import dataclasses
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ...core.errors import NodeError
from ...core.atomic import atomic_write_bytes
from ..io.bvh import Bvh, BvhJoint, POSITION_CHANNELS, bvh_positions, end_site_positions, quat_to_euler, read_bvh, write_bvh
from ..io.skeleton_map import axes_matrix
from ..kinematics import forward_kinematics
from ..quat import quat_apply, quat_mul

#: Largest angle (degrees) between the rest pose's hips->head direction and the application's up axis.
UPRIGHT_TOLERANCE_DEG = 30.0
#: Largest angle (degrees) between the rest pose's facing direction and the application's forward.
FACING_TOLERANCE_DEG = 45.0


@dataclass(frozen=True)
class Preset:
    """One export layout.

    ``file_axes``: for world x, y, z in turn, the file axis it equals (the convention of skeleton
    mapping YAML files, e.g. ``"x z -y"`` for a z-up file). ``units_per_metre``: file units per metre.
    ``rotation_order``: Euler channel order of every joint (intrinsic, as in BVH). ``naming``:
    ``"tbha"`` (the 16 names of :mod:`..skeleton`) or ``"mixamo"`` (renamed with the bundled mapping).
    ``app_axes``: for the application's x, y, z in turn, the file axis it equals after its import
    (Blender's default importer: ``"x -z y"``). ``app_up`` / ``app_forward``: signed application axes
    (``"z"``, ``"-y"``) the actor's head and face must point along in the rest pose.
    ``tolerance_m``: allowed read-back error of every joint, metres.
    """

    name: str
    summary: str
    file_axes: str = "x y z"
    units_per_metre: float = 1.0
    rotation_order: str = "ZXY"
    naming: str = "tbha"
    app: str = "y-up application"
    app_axes: str = "x y z"
    app_up: str = "y"
    app_forward: str = "z"
    import_settings: str = ""
    tolerance_m: float = 1e-4

    def world_from_file(self) -> np.ndarray:
        """(3, 3) rotation ``W`` with ``world = W @ file`` (directions; divide positions by the units)."""
        return axes_matrix(self.file_axes)

    def app_from_file(self) -> np.ndarray:
        """(3, 3) rotation ``A`` with ``application = A @ file`` (what the importer does)."""
        return axes_matrix(self.app_axes)

    def app_axis(self, which: str) -> np.ndarray:
        """Unit vector (3,) of a signed application axis name such as ``"-y"``."""
        sign = -1.0 if which.startswith("-") else 1.0
        v = np.zeros(3)
        v["xyz".index(which.lstrip("+-"))] = sign
        return v

    def replace(self, **changes) -> "Preset":
        return dataclasses.replace(self, **changes)


PRESETS: dict[str, Preset] = {
    "blender": Preset(
        name="blender",
        summary="Blender: y-up metre file for the importer's defaults (Forward -Z, Up Y); z up, faces -Y in Blender",
        units_per_metre=1.0,
        rotation_order="XYZ",
        app="Blender (default BVH import)",
        app_axes="x -z y",
        app_up="z",
        app_forward="-y",
        import_settings="File > Import > Motion Capture (.bvh): Forward -Z, Up Y, Scale 1.0, Rotation Native "
        "(the defaults; bpy.ops.import_anim.bvh(axis_forward='-Z', axis_up='Y'))",
    ),
    "y-up": Preset(
        name="y-up",
        summary="Maya / MotionBuilder / Unity: y up, faces +z, centimetres",
        units_per_metre=100.0,
        rotation_order="ZXY",
        app="Maya / MotionBuilder / Unity",
        import_settings="no axis conversion, scale 1 (the file is in centimetres); Unity BVH importers mirror x "
        "for its left-handed frame, keeping the actor facing +z",
    ),
    "mixamo": Preset(
        name="mixamo",
        summary="Mixamo rig names (mixamorig:*), T-pose rest, y up, faces +z, centimetres",
        units_per_metre=100.0,
        rotation_order="ZXY",
        naming="mixamo",
        app="Mixamo-named rig (Blender add-ons, Unreal IK Retargeter, Unity Humanoid)",
        import_settings="y up, centimetres; auto-map bones by their Mixamo names",
    ),
}

#: The layout of ``export.bvh`` without a preset: the capture's own axes (y up, faces +z), units and
#: Euler order from that node's ``scale`` / ``rotation_order`` params, the 16 TBHA names.
NATIVE = Preset(name="none", summary="the capture's own frame: y up, faces +z, units and Euler order from the params")

PRESET_NAMES: tuple[str, ...] = tuple(PRESETS)


def get_preset(name: str) -> Preset:
    """The preset called ``name`` (``"none"`` gives :data:`NATIVE`)."""
    if name == "none":
        return NATIVE
    try:
        return PRESETS[name]
    except KeyError:
        raise NodeError(f"unknown export preset {name!r}", hint=f"use one of: none, {', '.join(PRESETS)}") from None


# ---------------------------------------------------------------------------------------------
# writing: world -> file
# ---------------------------------------------------------------------------------------------
def _quat_of_matrix(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(m).as_quat()


def to_file_axes(
    preset: Preset, offsets: np.ndarray, ends: np.ndarray, local: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Convert a skeleton and its motion from world metres to the preset's file axes and units.

    ``offsets``, ``ends``: (J, 3) metres, world axes; ``local``: (n, J, 4) xyzw local rotations in world
    axes; ``root``: (n, 3) metres. A change of axes ``F`` (file = F world) turns every rotation ``q`` into
    ``F q F^-1`` and every vector ``v`` into ``F v``; lengths are multiplied by ``units_per_metre``.
    Returns ``(offsets, ends, local, root)`` in file axes and units.
    """
    f = preset.world_from_file().T
    qf = _quat_of_matrix(f)
    qf_inv = qf * np.array([-1.0, -1.0, -1.0, 1.0])
    u = preset.units_per_metre
    local_f = quat_mul(quat_mul(qf, local), qf_inv)
    return offsets @ f.T * u, ends @ f.T * u, local_f, root @ f.T * u


def build_bvh(
    names: Sequence[str],
    parents: np.ndarray,
    offsets: np.ndarray,
    ends: Sequence[np.ndarray | None],
    local: np.ndarray,
    root: np.ndarray,
    frame_time: float,
    orders: Sequence[str],
) -> Bvh:
    """A :class:`Bvh` with each joint's own Euler order (``orders``: J strings such as ``"ZXY"``).

    ``offsets`` (J, 3) and ``ends`` (per joint a (3,) End Site or ``None``) in file units; ``local``
    (n, J, 4) xyzw; ``root`` (n, 3). The root gets 6 channels (positions first), the others 3 rotation
    channels. Angles are unwrapped along time (no 360-degree jumps between frames).
    """
    n, nj = local.shape[0], len(names)
    angles = np.zeros((n, nj, 3))
    for order in sorted(set(orders)):
        cols = [j for j in range(nj) if orders[j] == order]
        angles[:, cols] = quat_to_euler(local[:, cols], order)
    if n > 1:
        angles = np.unwrap(angles, period=360.0, axis=0)
    joints = []
    for j, name in enumerate(names):
        rot = tuple(f"{a}rotation" for a in orders[j])
        chans = (POSITION_CHANNELS + rot) if j == 0 else rot
        end = None if ends[j] is None else np.asarray(ends[j], dtype=np.float64).reshape(3)
        joints.append(BvhJoint(str(name), int(parents[j]), np.asarray(offsets[j], dtype=np.float64).copy(), chans, end))
    motion = np.concatenate([root, angles.reshape(n, nj * 3)], axis=1)
    return Bvh(joints=joints, frame_time=float(frame_time), motion=motion)


# ---------------------------------------------------------------------------------------------
# checks
# ---------------------------------------------------------------------------------------------
@dataclass
class ReadBack:
    """A written file read back: ``positions`` (n, J, 3) and ``ends`` {joint: (n, 3)} in world metres,
    ``app_positions`` (n, J, 3) in the application's axes and metres, the :class:`Bvh` itself."""

    bvh: Bvh
    positions: np.ndarray
    ends: dict[int, np.ndarray]
    app_positions: np.ndarray


def read_back(path: Path, preset: Preset) -> ReadBack:
    """Read ``path`` with the project's reader; positions mapped back to world metres with the preset's
    declared axes and units, and to the application's axes."""
    back = read_bvh(path)
    file_pos = bvh_positions(back) / preset.units_per_metre
    w = preset.world_from_file()
    ends = {j: e / preset.units_per_metre @ w.T for j, e in end_site_positions(back).items()}
    return ReadBack(back, file_pos @ w.T, ends, file_pos @ preset.app_from_file().T)


def readback_error(got: ReadBack, want: np.ndarray, want_ends: dict[int, np.ndarray], checked: Sequence[int]) -> np.ndarray:
    """Per frame and checked joint, the distance (metres) between read-back and intended positions,
    shape (n, len(checked)); an End Site's error is folded into its joint's column."""
    checked = list(checked)
    err = np.linalg.norm(got.positions[:, checked] - want[:, checked], axis=-1)
    for col, j in enumerate(checked):
        if j in want_ends and j in got.ends:
            err[:, col] = np.maximum(err[:, col], np.linalg.norm(got.ends[j] - want_ends[j], axis=-1))
    return err


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na < 1e-12 or nb < 1e-12:
        return 180.0
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0))))


def orientation_error(preset: Preset, bvh: Bvh, hips: int, head: int, left: int, right: int) -> tuple[float, float]:
    """Angles (degrees) by which the file's rest pose, in the application's axes, misses standing
    upright (hips -> head vs ``app_up``) and facing forward (``(left - right) x up`` vs ``app_forward``).

    ``hips``, ``head``, ``left``, ``right``: joint indices in ``bvh`` (``left``/``right``: a left/right
    pair such as the hip joints).
    """
    nj = len(bvh.joints)
    rest, _ = forward_kinematics(bvh.parents, bvh.offsets, np.tile([0.0, 0.0, 0.0, 1.0], (1, nj, 1)), np.zeros((1, 3)))
    app = rest[0] @ preset.app_from_file().T
    up = preset.app_axis(preset.app_up)
    upright = _angle_deg(app[head] - app[hips], up)
    facing = np.cross(app[left] - app[right], up)
    return upright, _angle_deg(facing, preset.app_axis(preset.app_forward))


def verify_export(
    path: Path,
    preset: Preset,
    want: np.ndarray,
    want_ends: dict[int, np.ndarray],
    checked: Sequence[int],
    names: Sequence[str],
    orient: tuple[int, int, int, int],
) -> tuple[ReadBack, float]:
    """Run both self-checks on a written file; raise :class:`NodeError` naming the frame and joint on
    failure. ``want`` (n, J, 3) world metres; ``orient``: (hips, head, left, right) joint indices.
    Returns the read-back file and the worst joint error in metres."""
    got = read_back(path, preset)
    if got.positions.shape != want.shape:
        raise NodeError(f"self-check failed: {path.name} reads back with shape {got.positions.shape}, expected {want.shape}")
    err = readback_error(got, want, want_ends, checked)
    f, c = np.unravel_index(int(np.argmax(err)), err.shape)
    worst = float(err[f, c])
    if not worst <= preset.tolerance_m:
        raise NodeError(
            f"self-check failed: reading {path.name} back puts joint '{names[list(checked)[c]]}' {worst * 1000:.3f} mm "
            f"from the input on frame {f} (allowed {preset.tolerance_m * 1000:.1f} mm, preset '{preset.name}')",
            hint="raise 'precision' (decimals written) or, for small units, the scale; if it persists the axes "
            "conversion is wrong: report it",
        )
    upright, facing = orientation_error(preset, got.bvh, *orient)
    if upright > UPRIGHT_TOLERANCE_DEG or facing > FACING_TOLERANCE_DEG:
        raise NodeError(
            f"self-check failed: in {preset.app} the rest pose of {path.name} would lean {upright:.0f} degrees off "
            f"'{preset.app_up}' up and face {facing:.0f} degrees away from '{preset.app_forward}' "
            f"(allowed {UPRIGHT_TOLERANCE_DEG:.0f} and {FACING_TOLERANCE_DEG:.0f})",
            hint="the preset's file axes do not suit its application, or the skeleton's rest pose is not "
            "standing facing +z: check the mapping's 'axes'",
        )
    return got, worst


# ---------------------------------------------------------------------------------------------
# the contact sheet
# ---------------------------------------------------------------------------------------------
def contact_sheet(
    path: Path,
    preset: Preset,
    app_positions: np.ndarray,
    parents: np.ndarray,
    *,
    left: Sequence[int],
    right: Sequence[int],
    hips_pair: tuple[int, int],
    frames: int = 4,
    fps: float = 30.0,
    title: str = "",
) -> Path:
    """Draw ``frames`` evenly spaced frames of a skeleton, front and side views, in the application's axes.

    ``app_positions``: (n, J, 3) metres in the application's axes (:attr:`ReadBack.app_positions`);
    ``parents``: (J,); ``left`` / ``right``: joint indices drawn blue / red (the rest grey);
    ``hips_pair``: (left, right) joint indices giving the facing direction ``(left - right) x up``,
    drawn as a green arrow from the root in the side view. Front view: horizontal = the application
    axis the actor's left should point along, vertical = up; side view: horizontal = the axis the actor
    should face. Axes are flipped where needed so that "left" and "forward" point right on the page,
    and labelled with the application's own axis names and coordinates. The floor line is the clip's
    lowest point. Written atomically as PNG; returns ``path``. Drawn with Agg on a ``Figure`` of its own,
    without pyplot (whose figures and backend are process-wide: not safe beside nodes drawing in other threads).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    n = app_positions.shape[0]
    picks = np.unique(np.linspace(0, n - 1, max(1, min(frames, n))).round().astype(int))
    up = preset.app_axis(preset.app_up)
    fwd = preset.app_axis(preset.app_forward)
    k_up = int(np.argmax(np.abs(up)))
    floor = float(np.min(app_positions @ up))
    height = float(np.max(app_positions @ up)) - floor
    half = 0.5 * max(height, 0.5) + 0.1  # half the width of every panel, metres
    colours = ["0.35"] * len(parents)
    for j in left:
        colours[j] = "tab:blue"
    for j in right:
        colours[j] = "tab:red"
    bones = [j for j in range(len(parents)) if parents[j] >= 0]
    fig = Figure(figsize=(2.3 * len(picks) + 0.4, 5.4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(picks), squeeze=False)
    for col, f in enumerate(picks):
        p = app_positions[f]
        facing = np.cross(p[hips_pair[0]] - p[hips_pair[1]], up)
        facing /= max(float(np.linalg.norm(facing)), 1e-9)
        for row, (view, axis, what) in enumerate((("front", np.cross(up, fwd), "actor's left"), ("side", fwd, "forward"))):
            ax = axes[row, col]
            k = int(np.argmax(np.abs(axis)))
            x, y = p[:, k], (p @ up)
            segs = [((x[parents[j]], y[parents[j]]), (x[j], y[j])) for j in bones]
            ax.add_collection(LineCollection(segs, colors=[colours[j] for j in bones], linewidths=2))
            ax.plot(x, y, "o", ms=2, color="k")
            ax.axhline(floor, color="0.6", lw=1)
            cx = float(x[0])
            ax.set_xlim(cx - half, cx + half)
            ax.set_ylim(floor - 0.1, floor - 0.1 + 2 * half)
            if axis[k] < 0:
                ax.invert_xaxis()
            ax.set_aspect("equal")
            if view == "side":
                ax.annotate("", xy=(cx + 0.3 * facing[k], floor + 0.05), xytext=(cx, floor + 0.05),
                            arrowprops={"arrowstyle": "->", "color": "tab:green"})
            ax.xaxis.set_major_locator(MaxNLocator(3))
            ax.yaxis.set_major_locator(MaxNLocator(4))
            ax.tick_params(labelsize=6)
            sign = "-" if axis[k] < 0 else "+"
            ax.set_xlabel(f"{'XYZ'[k]}, m ({what} = {sign}{'XYZ'[k]} \u2192)", fontsize=7)
            ax.set_ylabel(f"{'XYZ'[k_up]} (up), m", fontsize=7)
            ax.set_title(f"{view}, frame {f} ({f / fps:.2f} s)", fontsize=7)
    fig.suptitle(title or f"{preset.app}: {preset.summary}", fontsize=8)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.09, top=0.88, wspace=0.45, hspace=0.38)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    path = Path(path)
    atomic_write_bytes(path, buf.getvalue())
    return path


def write_checked(
    path: Path,
    preset: Preset,
    *,
    names: Sequence[str],
    parents: np.ndarray,
    offsets: np.ndarray,
    ends: np.ndarray,
    end_mask: Sequence[bool],
    local: np.ndarray,
    root: np.ndarray,
    fps: float,
    orders: Sequence[str] | None = None,
    precision: int = 6,
    checked: Sequence[int] | None = None,
    orient: tuple[int, int, int, int],
) -> tuple[Path, ReadBack, float]:
    """Write a skeleton and its motion (world metres, world axes) in ``preset``'s layout and self-check it.

    ``offsets``/``ends`` (J, 3) metres world axes (``end_mask``: which joints have an End Site);
    ``local`` (n, J, 4) xyzw; ``root`` (n, 3) metres; ``orders``: per-joint Euler order (default: the
    preset's for every joint); ``checked``: joint indices compared on read-back (default all).
    Returns ``(path, read_back, worst_error_m)``; raises :class:`NodeError` when a check fails.
    """
    nj = len(names)
    want, world = forward_kinematics(parents, offsets, local, root)
    want_ends = {j: want[:, j] + quat_apply(world[:, j], ends[j]) for j in range(nj) if end_mask[j]}
    off_f, ends_f, local_f, root_f = to_file_axes(preset, offsets, ends, local, root)
    bvh = build_bvh(
        names, parents, off_f, [ends_f[j] if end_mask[j] else None for j in range(nj)], local_f, root_f,
        1.0 / fps, orders or [preset.rotation_order] * nj,
    )
    path = write_bvh(path, bvh, precision=precision)
    got, worst = verify_export(path, preset, want, want_ends, range(nj) if checked is None else checked, names, orient)
    return path, got, worst
