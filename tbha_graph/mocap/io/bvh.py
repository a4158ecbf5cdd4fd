"""Reading and writing BVH motion files, and converting their channels to quaternions and positions
(and quaternions back to channel angles: :func:`quat_to_euler`).

A BVH file has a ``HIERARCHY`` (a joint tree: per joint an ``OFFSET`` from its parent in file units,
a ``CHANNELS`` list, children and optional ``End Site``) and a ``MOTION`` block (one line of channel
values per frame, in hierarchy order). Conventions implemented here (those of real exporters):

* Rotation channels are Euler angles in degrees, intrinsic, applied in the order listed: a joint with
  ``Zrotation Xrotation Yrotation`` has local rotation ``R = Rz(a) @ Rx(b) @ Ry(c)``. Each joint keeps
  its own order (CMU files mix ``ZYX`` and ``ZXY`` within one file).
* Position channels give a joint's translation from its parent, replacing its ``OFFSET`` for the
  components present; for the root they are its absolute position (the root ``OFFSET`` is only used
  when the root has no position channels).
* ``world_rot[j] = world_rot[parent] * local[j]``; ``pos[j] = pos[parent] + world_rot[parent] (offset[j])``
  (see :func:`tbha_graph.mocap.kinematics.forward_kinematics`).

The reader accepts mixed CRLF/LF/CR line endings, tabs or spaces, zero offsets, 6-channel non-root
joints and any ``Frame Time`` precision; a malformed file raises :class:`BvhError` naming ``file:line``
and what was expected, and nothing partial is returned. The writer is atomic and writes LF + tabs.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ...core.errors import Location, NodeError
from ...core.atomic import atomic_write_bytes
from ..kinematics import forward_kinematics, validate_parents
from ..quat import quat_apply, quat_mul

#: Channel names as written in files (matched case-insensitively when reading).
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
_CANONICAL = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}
_AXIS = {"X": 0, "Y": 1, "Z": 2}


class BvhError(NodeError):
    """A BVH file that cannot be read: ``location`` holds the file and 1-based line."""


@dataclass
class BvhJoint:
    """One joint of a BVH hierarchy.

    ``offset``: (3,) float64, file units, from the parent joint in the parent's rest frame.
    ``channels``: canonical channel names in file order (``"Xposition"``, ``"Zrotation"``, ...).
    ``end_site``: (3,) End Site offset in file units, or ``None``.
    """

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    end_site: np.ndarray | None = None


@dataclass
class Bvh:
    """A BVH file in memory: joints in file (depth-first) order, root first.

    ``motion``: (n_frames, n_channels) float64, the channel values exactly as in the file (degrees for
    rotations, file units for positions), columns in joint order then each joint's channel order.
    """

    joints: list[BvhJoint]
    frame_time: float
    motion: np.ndarray
    _starts: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        counts = [len(j.channels) for j in self.joints]
        self._starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def parents(self) -> np.ndarray:
        """(J,) int64 parent index, -1 for the root."""
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @property
    def offsets(self) -> np.ndarray:
        """(J, 3) float64 rest offsets, file units."""
        return np.array([j.offset for j in self.joints], dtype=np.float64).reshape(-1, 3)

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def n_channels(self) -> int:
        return int(sum(len(j.channels) for j in self.joints))

    def joint_index(self, name: str) -> int:
        for i, j in enumerate(self.joints):
            if j.name == name:
                return i
        raise KeyError(f"no joint {name!r} in this BVH")

    def channel_index(self, joint: str | int, channel: str) -> int:
        """Column of ``motion`` holding ``channel`` (e.g. ``"Zrotation"``) of ``joint`` (name or index)."""
        j = self.joint_index(joint) if isinstance(joint, str) else int(joint)
        chans = [c.lower() for c in self.joints[j].channels]
        if channel.lower() not in chans:
            raise KeyError(f"joint {self.joints[j].name!r} has no channel {channel!r} (has {self.joints[j].channels})")
        return int(self._starts[j]) + chans.index(channel.lower())


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
#: a plain decimal number as BVH writers print it (float() alone also takes '1_0', 'infinity', '١')
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


class _Tokens:
    """Header tokens with their 1-based line numbers; raises BvhError with ``file:line``."""

    def __init__(self, toks: list[tuple[str, int]], file: str, end_line: int):
        self.toks = toks
        self.i = 0
        self.file = file
        self.end_line = end_line

    def error(self, msg: str, line: int | None = None, hint: str = "") -> BvhError:
        if line is None:
            line = self.toks[self.i][1] if self.i < len(self.toks) else self.end_line
        return BvhError(msg, location=Location(self.file, line), hint=hint)

    def peek(self) -> str | None:
        return self.toks[self.i][0] if self.i < len(self.toks) else None

    def next(self, what: str) -> tuple[str, int]:
        if self.i >= len(self.toks):
            raise self.error(f"file ended inside the HIERARCHY, expected {what}", self.end_line)
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def expect(self, word: str, where: str = "") -> int:
        tok, line = self.next(f"'{word}'")
        if tok.upper() != word.upper():
            raise self.error(f"{where}expected '{word}', found '{tok}'", line)
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        if not _DECIMAL.fullmatch(tok):
            raise self.error(f"expected {what} (a number), found '{tok}'", line)
        value = float(tok)
        if not np.isfinite(value):
            raise self.error(f"expected {what} (a finite number), found '{tok}'", line)
        return value

    def vec3(self, what: str) -> np.ndarray:
        return np.array([self.number(f"{what} {ax}") for ax in "xyz"], dtype=np.float64)


def _parse_joint(t: _Tokens, name: str, parent: int, joints: list[BvhJoint]) -> None:
    where = f"joint '{name}': "
    t.expect("{", where)
    t.expect("OFFSET", where)
    offset = t.vec3("OFFSET")
    t.expect("CHANNELS", where)
    n_tok, n_line = t.next("the channel count")
    if not (n_tok.isascii() and n_tok.isdigit()):
        raise t.error(f"expected the channel count after CHANNELS, found '{n_tok}'", n_line)
    chans = []
    for _ in range(int(n_tok)):
        c, line = t.next("a channel name")
        canon = _CANONICAL.get(c.lower())
        if canon is None:
            raise t.error(
                f"joint '{name}': unknown channel '{c}'",
                line,
                hint=f"channels are {', '.join(POSITION_CHANNELS + ROTATION_CHANNELS)}; "
                f"check the CHANNELS count ({n_tok}) matches the names listed",
            )
        if canon in chans:
            raise t.error(f"joint '{name}': channel '{c}' listed twice", line)
        chans.append(canon)
    index = len(joints)
    joints.append(BvhJoint(name, parent, offset, tuple(chans), None))
    while True:
        tok = t.peek()
        if tok is None:
            raise t.error(f"file ended inside joint '{name}', expected '}}'", t.end_line)
        word, line = t.next("'JOINT', 'End Site' or '}'")
        up = word.upper()
        if up == "}":
            return
        if up == "JOINT":
            child, _ = t.next("a joint name")
            _parse_joint(t, child, index, joints)
        elif up == "END":
            if (t.peek() or "").upper() == "SITE":
                t.next("'Site'")
            if joints[index].end_site is not None:
                raise t.error(f"joint '{name}' has two End Sites", line)
            where = f"End Site of joint '{name}': "
            t.expect("{", where)
            t.expect("OFFSET", where)
            joints[index].end_site = t.vec3("End Site OFFSET")
            t.expect("}", where)
        else:
            raise t.error(f"inside joint '{name}': expected 'JOINT', 'End Site' or '}}', found '{word}'", line)


def _find_bad_motion_line(lines: list[str], first_line: int, n_channels: int, file: str) -> BvhError:
    """Slow path after a fast parse failed: locate the first offending motion line."""
    for k, text in enumerate(lines):
        vals = text.split()
        if not vals:
            continue
        line = first_line + k
        if len(vals) != n_channels:
            return BvhError(
                f"motion line has {len(vals)} values, expected {n_channels} (one per channel in the HIERARCHY)",
                location=Location(file, line),
            )
        for col, v in enumerate(vals):
            try:
                x = float(v)
            except ValueError:
                x = float("nan")
            if not np.isfinite(x):
                return BvhError(
                    f"value {col + 1} is '{v}', expected a finite number", location=Location(file, line)
                )
    return BvhError("motion block could not be parsed", location=Location(file, first_line))


_HEADER_FIELD = re.compile(r"^\s*(frames|frame\s+time)\s*:\s*(\S*)\s*$", re.IGNORECASE)


def read_bvh(path: str | Path) -> Bvh:
    """Read a BVH file. Raises :class:`BvhError` (a ``NodeError``) naming ``file:line`` when malformed."""
    path = Path(path)
    file = str(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise BvhError(f"cannot read BVH file: {e.strerror or e}", location=Location(file)) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    lines = _LINE_BREAK.split(text)

    # header tokens up to the MOTION keyword
    toks: list[tuple[str, int]] = []
    motion_line = None
    for k, line in enumerate(lines):
        words = line.split()
        if words and words[0].upper() == "MOTION":
            motion_line = k
            break
        toks.extend((w, k + 1) for w in words)
    if motion_line is None:
        last = max((k + 1 for k, s in enumerate(lines) if s.strip()), default=1)
        raise BvhError("no MOTION section found", location=Location(file, last),
                       hint="a BVH file has a HIERARCHY, then 'MOTION', 'Frames: N', 'Frame Time: T'")
    t = _Tokens(toks, file, motion_line + 1)
    t.expect("HIERARCHY")
    joints: list[BvhJoint] = []
    t.expect("ROOT")
    root_name, _ = t.next("the root joint name")
    _parse_joint(t, root_name, -1, joints)
    if t.peek() is not None:
        word, line = t.next("")
        if word.upper() == "ROOT":
            raise t.error("a second ROOT: only BVH files with one root joint are supported", line)
        raise t.error(f"unexpected '{word}' after the closing '}}' of the hierarchy, expected 'MOTION'", line)
    names = [j.name for j in joints]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise BvhError(f"joint name(s) used twice: {dup}", location=Location(file, 1),
                       hint="joint names must be unique")

    # Frames / Frame Time
    values: dict[str, tuple[str, int]] = {}
    k = motion_line + 1
    while len(values) < 2:
        if k >= len(lines):
            raise BvhError("file ended before 'Frames:' and 'Frame Time:'", location=Location(file, k))
        if lines[k].strip():
            m = _HEADER_FIELD.match(lines[k])
            want = "Frames:" if not values else "Frame Time:"
            if m is None or ("time" in m.group(1).lower()) != bool(values):
                raise BvhError(f"expected '{want}', found '{lines[k].strip()[:40]}'", location=Location(file, k + 1))
            values["time" if values else "frames"] = (m.group(2), k + 1)
        k += 1
    frames_s, frames_line = values["frames"]
    if not (frames_s.isascii() and frames_s.isdigit()):
        raise BvhError(f"expected a whole number of frames after 'Frames:', found '{frames_s}'",
                       location=Location(file, frames_line))
    n_frames = int(frames_s)
    time_s, time_line = values["time"]
    frame_time = float(time_s) if _DECIMAL.fullmatch(time_s) else float("nan")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise BvhError(f"expected a positive number of seconds after 'Frame Time:', found '{time_s}'",
                       location=Location(file, time_line))

    # motion block: fast numpy parse, slow path only to locate an error
    first = k + 1  # 1-based line number of the first motion line
    body = lines[k:]
    n_channels = sum(len(j.channels) for j in joints)
    nonblank = [i for i, s in enumerate(body) if s.strip()]
    if len(nonblank) != n_frames:
        if len(nonblank) < n_frames:
            raise BvhError(
                f"truncated motion: 'Frames: {n_frames}' but only {len(nonblank)} motion lines",
                location=Location(file, first + (nonblank[-1] if nonblank else -1)),
                hint="the file was cut short; re-export it, or set 'Frames:' to the number of lines present",
            )
        raise BvhError(
            f"'Frames: {n_frames}' but {len(nonblank)} motion lines; line {first + nonblank[n_frames]} is extra",
            location=Location(file, frames_line),
            hint="set 'Frames:' to the number of motion lines",
        )
    if n_frames == 0:
        motion = np.zeros((0, n_channels))
    elif n_channels == 0:
        raise BvhError("the HIERARCHY declares no channels", location=Location(file, 1))
    else:
        try:
            motion = np.loadtxt(body, dtype=np.float64, comments=None, ndmin=2)
        except ValueError:
            raise _find_bad_motion_line(body, first, n_channels, file) from None
        if motion.shape != (n_frames, n_channels) or not np.isfinite(motion).all():
            raise _find_bad_motion_line(body, first, n_channels, file)
    return Bvh(joints=joints, frame_time=frame_time, motion=motion)


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------
def _rounded(a: np.ndarray, p: int) -> np.ndarray:
    """``a`` rounded to ``p`` decimals, + 0.0 so no "-0.000" is printed. np.round overflows to inf
    for |x| > ~1e308 / 10**p, so values beyond 1e15 (already whole at float64 precision) are kept."""
    a = np.asarray(a, dtype=np.float64)
    small = np.abs(a) < 1e15
    return np.where(small, np.round(np.where(small, a, 0.0), p), a) + 0.0


def write_bvh(path: str | Path, bvh: Bvh, precision: int = 6) -> Path:
    """Write ``bvh`` to ``path`` atomically (temp file + rename), LF line endings, tab indentation.

    Offsets and channel values are printed with ``precision`` decimals; ``Frame Time`` is printed
    exactly (shortest repr). Returns the path.
    """
    path = Path(path)
    validate_parents(bvh.parents)
    children: list[list[int]] = [[] for _ in bvh.joints]
    for i, j in enumerate(bvh.joints[1:], start=1):
        children[j.parent].append(i)
    p = int(precision)
    out: list[str] = ["HIERARCHY"]

    def vec(v: np.ndarray) -> str:
        return " ".join(f"{float(x):.{p}f}" for x in _rounded(v, p))

    def emit(i: int, depth: int) -> None:
        j = bvh.joints[i]
        ind = "\t" * depth
        out.append(f"{ind}{'ROOT' if i == 0 else 'JOINT'} {j.name}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {vec(j.offset)}")
        out.append(f"{ind}\tCHANNELS {len(j.channels)}{''.join(' ' + c for c in j.channels)}")
        for c in children[i]:
            emit(c, depth + 1)
        if j.end_site is not None:
            out.extend([f"{ind}\tEnd Site", f"{ind}\t{{", f"{ind}\t\tOFFSET {vec(j.end_site)}", f"{ind}\t}}"])
        out.append(f"{ind}}}")

    emit(0, 0)
    motion = np.asarray(bvh.motion, dtype=np.float64)
    if motion.ndim != 2 or motion.shape[1] != bvh.n_channels:
        raise ValueError(f"motion must have shape (n_frames, {bvh.n_channels}), got {motion.shape}")
    if not np.isfinite(motion).all():
        raise ValueError("motion holds NaN or infinite values")
    out += ["MOTION", f"Frames: {motion.shape[0]}", f"Frame Time: {float(bvh.frame_time)!r}"]
    row = " ".join([f"%.{p}f"] * motion.shape[1])
    out.extend(row % tuple(r) for r in _rounded(motion, p).tolist())
    atomic_write_bytes(path, ("\n".join(out) + "\n").encode("utf-8"))  # joint names may be non-ASCII
    return path


# ---------------------------------------------------------------------------------------------
# channels <-> rotations
# ---------------------------------------------------------------------------------------------
def _rotation_layout(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """Per joint up to 3 rotation channels: columns ``(J, 3)`` (-1 = none) and axes ``(J, 3)`` (0/1/2)."""
    cols = np.full((len(bvh.joints), 3), -1, dtype=np.int64)
    axes = np.zeros((len(bvh.joints), 3), dtype=np.int64)
    for i, j in enumerate(bvh.joints):
        k = 0
        for c in j.channels:
            if c.endswith("rotation"):
                cols[i, k] = bvh.channel_index(i, c)
                axes[i, k] = _AXIS[c[0]]
                k += 1
    return cols, axes


def bvh_to_local(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations and root position from the channels, each joint in its own Euler order.

    Returns ``local_quat`` ``(n_frames, J, 4)`` xyzw (``R = R_first @ R_second @ R_third`` in the
    listed channel order) and ``root_position`` ``(n_frames, 3)`` file units (the root's position
    channels, or its OFFSET where a component has no channel).
    """
    n, nj = bvh.n_frames, len(bvh.joints)
    cols, axes = _rotation_layout(bvh)
    angles = np.where(cols >= 0, bvh.motion[:, np.maximum(cols, 0)], 0.0)  # (n, J, 3) degrees
    half = np.deg2rad(angles) * 0.5
    q = np.array([0.0, 0.0, 0.0, 1.0]) * np.ones((n, nj, 1))
    jidx = np.arange(nj)
    for k in range(3):
        qk = np.zeros((n, nj, 4))
        qk[:, jidx, axes[:, k]] = np.sin(half[:, :, k])
        qk[:, :, 3] = np.cos(half[:, :, k])
        q = quat_mul(q, qk)
    return q, _translations(bvh)[:, 0]


def _translations(bvh: Bvh) -> np.ndarray:
    """Per-frame translation of every joint from its parent ``(n, J, 3)``: OFFSET, overridden by position channels."""
    trans = np.broadcast_to(bvh.offsets, (bvh.n_frames, len(bvh.joints), 3)).copy()
    for i, j in enumerate(bvh.joints):
        for c in j.channels:
            if c.endswith("position"):
                trans[:, i, _AXIS[c[0]]] = bvh.motion[:, bvh.channel_index(i, c)]
    return trans


def bvh_positions(bvh: Bvh) -> np.ndarray:
    """World positions ``(n_frames, J, 3)`` of every joint in file units (forward kinematics)."""
    local, root = bvh_to_local(bvh)
    trans = _translations(bvh)
    has_pos = any(c.endswith("position") for j in bvh.joints[1:] for c in j.channels)
    offsets = trans if has_pos else bvh.offsets
    return forward_kinematics(bvh.parents, offsets, local, root)[0]


def end_site_positions(bvh: Bvh) -> dict[int, np.ndarray]:
    """World positions ``(n_frames, 3)`` of the End Sites, keyed by the index of the joint that holds them."""
    local, root = bvh_to_local(bvh)
    trans = _translations(bvh)
    has_pos = any(c.endswith("position") for j in bvh.joints[1:] for c in j.channels)
    pos, world = forward_kinematics(bvh.parents, trans if has_pos else bvh.offsets, local, root)
    return {i: pos[:, i] + quat_apply(world[:, i], j.end_site) for i, j in enumerate(bvh.joints) if j.end_site is not None}


def _check_order(order: str) -> str:
    up = order.upper()
    if len(up) != 3 or sorted(up) != ["X", "Y", "Z"]:
        raise ValueError(f"rotation order must be a permutation of 'XYZ' (e.g. 'ZXY'), got {order!r}")
    return up


def quat_to_euler(q: np.ndarray, order: str) -> np.ndarray:
    """Euler angles ``(..., 3)`` degrees, intrinsic, in the channel order ``order`` (a permutation of
    ``"XYZ"``, e.g. ``"ZXY"``: ``R = Rz(a) @ Rx(b) @ Ry(c)``), of quaternions ``q`` ``(..., 4)`` xyzw: the
    inverse of :func:`bvh_to_local`'s conversion. At gimbal lock (middle angle +-90 degrees) the third
    angle is 0 and the angles still give the rotation; no warning is emitted."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, dtype=np.float64)
    r = Rotation.from_quat(q.reshape(-1, 4))
    order = _check_order(order)
    # scipy >= 1.17 (the floor in pyproject.toml) can be told not to warn at gimbal lock: no process-wide
    # warnings.catch_warnings, which is not thread-safe before Python 3.14 and nodes run in threads
    eul = r.as_euler(order, degrees=True, suppress_warnings=True)
    return eul.reshape(q.shape[:-1] + (3,))


def bvh_from_local(
    names: Sequence[str],
    parents: np.ndarray,
    offsets: np.ndarray,
    end_sites: Sequence[np.ndarray | None] | np.ndarray | None,
    local_quat: np.ndarray,
    root_position: np.ndarray,
    frame_time: float,
    order: str = "ZXY",
) -> Bvh:
    """Build a :class:`Bvh` from local rotations (the inverse of :func:`bvh_to_local`).

    Args:
        names: J joint names; parents: (J,) parent indices (root 0 first, parents before children).
        offsets: (J, 3) rest offsets in file units; end_sites: per joint a (3,) End Site offset or
            ``None``; or a (J, 3) array, whose rows are used for the leaf joints only.
        local_quat: (n, J, 4) xyzw; root_position: (n, 3) file units; frame_time: seconds.
        order: Euler channel order used for every joint (intrinsic, e.g. ``"ZXY"``); the root gets
            ``Xposition Yposition Zposition`` followed by its rotation channels.
    Angles are unwrapped along time (no 360-degree jumps between consecutive frames).
    """
    order = _check_order(order)
    parents = validate_parents(parents)
    nj = len(names)
    local_quat = np.asarray(local_quat, dtype=np.float64)
    root_position = np.asarray(root_position, dtype=np.float64)
    n = local_quat.shape[0]
    if local_quat.shape != (n, nj, 4) or parents.shape != (nj,) or root_position.shape != (n, 3):
        raise ValueError(
            f"shapes do not agree: {nj} names, parents {parents.shape}, local_quat {local_quat.shape}, "
            f"root_position {root_position.shape}"
        )
    offsets = np.asarray(offsets, dtype=np.float64).reshape(nj, 3)
    is_leaf = np.ones(nj, dtype=bool)
    is_leaf[parents[parents >= 0]] = False
    if end_sites is None:
        ends: list[np.ndarray | None] = [None] * nj
    elif isinstance(end_sites, np.ndarray):
        arr = end_sites.reshape(nj, 3)
        ends = [arr[i].astype(np.float64) if is_leaf[i] else None for i in range(nj)]
    else:
        ends = [None if e is None else np.asarray(e, dtype=np.float64).reshape(3) for e in end_sites]
    eul = quat_to_euler(local_quat, order)
    if n > 1:
        eul = np.unwrap(eul, period=360.0, axis=0)
    rot_names = tuple(f"{a}rotation" for a in order)
    joints = [
        BvhJoint(str(nm), int(parents[i]), offsets[i].copy(), (POSITION_CHANNELS + rot_names) if i == 0 else rot_names, ends[i])
        for i, nm in enumerate(names)
    ]
    motion = np.concatenate([root_position, eul.reshape(n, nj * 3)], axis=1)
    return Bvh(joints=joints, frame_time=float(frame_time), motion=motion)
