"""Static backgrounds behind the actor, and soft contact shadows on the floor.

``plain``: one colour. ``room``: a tiled floor (plane y = 0) and a plastered wall (plane
z = -wall_distance, facing +z), world frame metres, lit by the same key light as the body. The
camera is fixed, so the background is computed once per video; :func:`contact_shadows` darkens the
floor under the hips and the feet each frame.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..camera import Camera
from ..skeleton import JOINT_INDEX

_FAR = np.float32(1e6)


def hex_rgb(hx: str) -> np.ndarray:
    """'#rrggbb' -> RGB floats in [0, 1], shape (3,)."""
    s = hx.lstrip("#")
    return np.array([int(s[i : i + 2], 16) for i in (0, 2, 4)], dtype=np.float64) / 255.0


def _world_rays(camera: Camera) -> np.ndarray:
    """Unnormalised world-frame ray directions (H, W, 3) through every pixel centre."""
    u = np.arange(camera.width, dtype=np.float64)
    v = np.arange(camera.height, dtype=np.float64)
    uu, vv = np.meshgrid(u, v)
    pix = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
    d_cam = pix @ np.linalg.inv(camera.K).T
    return d_cam @ camera.R  # R^T d for row vectors


def make_background(
    camera: Camera,
    kind: str,
    colour: str,
    light_dir,
    rng: np.random.Generator,
    wall_distance: float = 3.0,
    tile_size: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Background image (H, W, 3) BGR uint8 and floor coordinates (H, W, 2) float32 world (x, z) metres
    of each pixel on the floor (a huge value where the pixel does not see the floor)."""
    H, W = camera.height, camera.width
    floor_xz = np.full((H, W, 2), _FAR, dtype=np.float32)
    if kind == "plain":
        bgr = (hex_rgb(colour)[::-1] * 255 + 0.5).astype(np.uint8)
        return np.broadcast_to(bgr, (H, W, 3)).copy(), floor_xz
    L = np.asarray(light_dir, dtype=np.float64)
    L = L / np.linalg.norm(L)
    C = camera.center
    d = _world_rays(camera)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[..., 1] < 0, -C[1] / d[..., 1], np.inf)
        t_wall = np.where(d[..., 2] < 0, (-wall_distance - C[2]) / d[..., 2], np.inf)
    on_floor = t_floor < t_wall
    t = np.where(on_floor, t_floor, t_wall)
    P = C + np.where(np.isfinite(t), t, 0.0)[..., None] * d
    # floor: tiles with grout, each tile a slightly different tint
    tint = 0.92 + 0.08 * rng.random((32, 32))
    ix = np.floor(P[..., 0] / tile_size).astype(np.int64) % 32
    iz = np.floor(P[..., 2] / tile_size).astype(np.int64) % 32
    fx = np.abs((P[..., 0] / tile_size) - np.round(P[..., 0] / tile_size)) * tile_size
    fz = np.abs((P[..., 2] / tile_size) - np.round(P[..., 2] / tile_size)) * tile_size
    grout = np.clip((np.minimum(fx, fz) - 0.004) / 0.004, 0.0, 1.0)
    floor_rgb = np.array([0.62, 0.55, 0.47]) * (tint[ix, iz] * (0.55 + 0.45 * grout))[..., None]
    floor_lin = floor_rgb**2 * (0.35 + 0.75 * max(L[1], 0.0))
    # wall: plaster with faint large-scale blotches and a darker skirting board
    blotch = cv2.resize(rng.random((12, 16)).astype(np.float32), (W, H), interpolation=cv2.INTER_CUBIC)
    wall_rgb = np.array([0.80, 0.78, 0.72]) * (0.95 + 0.05 * blotch)[..., None]
    wall_rgb = np.where((P[..., 1] < 0.12)[..., None], np.array([0.45, 0.42, 0.38]), wall_rgb)
    wall_lin = wall_rgb**2 * (0.35 + 0.75 * max(L[2], 0.0))
    lin = np.where(on_floor[..., None], floor_lin, wall_lin)
    lin = np.where(np.isfinite(t)[..., None], lin, 0.0)
    grain = rng.normal(0.0, 0.012, size=(H, W, 1))
    srgb = np.sqrt(np.clip(lin, 0.0, 1.0)) + grain
    img = np.clip(srgb[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8)
    img = cv2.GaussianBlur(img, (0, 0), 0.6)
    floor_xz[on_floor] = P[on_floor][:, [0, 2]].astype(np.float32)
    return img, floor_xz


#: (joint, shadow radius m, darkening at rest, rest height m) of the soft blob shadows
_CASTERS = (("hips", 0.30, 0.30, 0.95), ("left_ankle", 0.11, 0.45, 0.08), ("right_ankle", 0.11, 0.45, 0.08))


def contact_shadows(image: np.ndarray, floor_xz: np.ndarray, joints: np.ndarray, camera: Camera) -> None:
    """Darken ``image`` (H, W, 3) BGR uint8 in place under the hips and the feet (soft blobs on the
    floor that fade as a foot lifts). ``joints`` (16, 3) world metres."""
    for name, radius, strength, rest in _CASTERS:
        p = joints[JOINT_INDEX[name]]
        s = strength * float(np.clip(1.0 - (p[1] - rest) / 0.35, 0.0, 1.0))
        if s <= 0.01:
            continue
        ext = 2.0 * radius
        corners = np.array([[p[0] + dx, 0.0, p[2] + dz] for dx in (-ext, ext) for dz in (-ext, ext)])
        cam = camera.to_camera(corners)
        if np.any(cam[:, 2] < 0.05):
            continue
        px = camera.project(corners)
        u0, v0 = np.floor(px.min(axis=0)).astype(int)
        u1, v1 = np.ceil(px.max(axis=0)).astype(int) + 1
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, camera.width), min(v1, camera.height)
        if u0 >= u1 or v0 >= v1:
            continue
        xz = floor_xz[v0:v1, u0:u1]
        d2 = (xz[..., 0] - np.float32(p[0])) ** 2 + (xz[..., 1] - np.float32(p[2])) ** 2
        factor = 1.0 - np.float32(s) * np.exp(-d2 / np.float32(radius * radius))
        region = image[v0:v1, u0:u1]
        region[:] = (region * factor[..., None] + 0.5).astype(np.uint8)
