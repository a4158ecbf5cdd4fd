"""Ray-cast rasteriser with a depth buffer, for the body's affine capsules in the camera frame.

Camera frame as in :mod:`tbha_graph.mocap.camera` (metres, x right, y down, z forward). The ray through
pixel ``(u, v)`` is ``d = ((u - cx) / fx, (v - cy) / fy, 1)``: a point ``t * d`` has depth ``z = t``,
so the depth buffer holds camera-frame ``z`` in metres (lens distortion is not modelled here).

Each primitive is intersected exactly (closed-form quadratic) over the pixels of its projected
bounding box, vectorised with numpy in float32; no per-pixel Python loops. Buffers, shape
``(height, width)``: ``depth`` float32 metres (``inf`` = background), ``prim`` int16 primitive id
(``-1`` = background). Surface normals are computed afterwards, only for the pixels that stayed
visible (:meth:`Raster.normals`), in one vectorised pass over all primitives.
"""
from __future__ import annotations

import numpy as np

from .body import BodyGeometry

NEAR = 0.05  # metres: primitives with any part nearer than this are not drawn


class Raster:
    """Depth and primitive-id buffers of one image, the per-pixel ray directions, and what is needed to
    compute normals of the visible pixels."""

    def __init__(self, K: np.ndarray, width: int, height: int):
        K = np.asarray(K, dtype=np.float64)
        if abs(K[0, 1]) > 1e-9:
            raise ValueError("skewed intrinsics are not supported by the rasteriser")
        self.K = K
        self.width, self.height = int(width), int(height)
        self.dx = ((np.arange(self.width) - K[0, 2]) / K[0, 0]).astype(np.float32)
        self.dy = ((np.arange(self.height) - K[1, 2]) / K[1, 1]).astype(np.float32)
        self.dd = (self.dx[None, :] ** 2 + self.dy[:, None] ** 2 + 1.0).astype(np.float32)
        self.depth = np.full((self.height, self.width), np.inf, dtype=np.float32)
        self.prim = np.full((self.height, self.width), -1, dtype=np.int16)
        self._params = np.zeros((0, 16), dtype=np.float32)  # per primitive, for normals (see _remember)
        self.region: tuple[int, int, int, int] | None = None  # (v0, v1, u0, u1) drawn last time

    # ------------------------------------------------------------------------------------------
    def clear(self) -> None:
        """Reset the buffers where the last frame drew."""
        if self.region is not None:
            v0, v1, u0, u1 = self.region
            self.depth[v0:v1, u0:u1] = np.inf
            self.prim[v0:v1, u0:u1] = -1
        self.region = None

    def bbox(self, lo: np.ndarray, hi: np.ndarray) -> tuple[int, int, int, int] | None:
        """Pixel box (v0, v1, u0, u1), clipped to the image, holding the projection of the camera-frame
        axis-aligned box [lo, hi] (3,); ``None`` if it is empty or reaches nearer than :data:`NEAR`."""
        z0, z1 = float(lo[2]), float(hi[2])
        if z0 < NEAR:
            return None
        K = self.K
        # x / z over the box is extreme at its corners: min and max over the two depths
        xs = (float(lo[0]) / z0, float(lo[0]) / z1, float(hi[0]) / z0, float(hi[0]) / z1)
        ys = (float(lo[1]) / z0, float(lo[1]) / z1, float(hi[1]) / z0, float(hi[1]) / z1)
        u0 = max(int(np.floor(min(xs) * K[0, 0] + K[0, 2])), 0)
        u1 = min(int(np.ceil(max(xs) * K[0, 0] + K[0, 2])) + 1, self.width)
        v0 = max(int(np.floor(min(ys) * K[1, 1] + K[1, 2])), 0)
        v1 = min(int(np.ceil(max(ys) * K[1, 1] + K[1, 2])) + 1, self.height)
        if u0 >= u1 or v0 >= v1:
            return None
        return v0, v1, u0, u1

    def _grow(self, box: tuple[int, int, int, int]) -> None:
        if self.region is None:
            self.region = box
        else:
            r = self.region
            self.region = (min(r[0], box[0]), max(r[1], box[1]), min(r[2], box[2]), max(r[3], box[3]))

    def _commit(self, box, t, hit, k: int) -> None:
        """Write primitive ``k``'s hits (depth ``t`` (h, w)) that are nearer than the buffer."""
        v0, v1, u0, u1 = box
        zs = self.depth[v0:v1, u0:u1]
        win = hit & (t < zs) & (t > NEAR)
        np.copyto(zs, t, where=win)
        np.copyto(self.prim[v0:v1, u0:u1], np.int16(k), where=win)
        self._grow(box)

    def _remember(self, k: int, Ml: np.ndarray, al: np.ndarray, u: np.ndarray, L: float) -> None:
        """Keep primitive ``k``'s parameters for :meth:`normals`: one row of 16 floats
        (map to its own space (9), end a there (3), unit axis there (3), length (1))."""
        if k >= self._params.shape[0]:
            self._params = np.concatenate([self._params, np.zeros((k + 1 - self._params.shape[0], 16), np.float32)])
        self._params[k, :9] = Ml.reshape(-1)
        self._params[k, 9:12] = al
        self._params[k, 12:15] = u
        self._params[k, 15] = L

    def normals(self, v: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit outward normals at body pixels (rows ``v``, columns ``u``), camera frame, as three float32
        arrays (nx, ny, nz) of shape (N,) (component arrays: cheaper than (N, 3) reductions)."""
        g = self._params[self.prim[v, u]]  # (N, 16)
        z = self.depth[v, u]
        px, py = self.dx[u] * z, self.dy[v] * z
        # point in the capsule's own space, relative to its end a
        wx = g[:, 0] * px + g[:, 1] * py + g[:, 2] * z - g[:, 9]
        wy = g[:, 3] * px + g[:, 4] * py + g[:, 5] * z - g[:, 10]
        wz = g[:, 6] * px + g[:, 7] * py + g[:, 8] * z - g[:, 11]
        along = np.clip(wx * g[:, 12] + wy * g[:, 13] + wz * g[:, 14], 0.0, g[:, 15])
        wx -= along * g[:, 12]
        wy -= along * g[:, 13]
        wz -= along * g[:, 14]
        # gradient back in camera coordinates: M^T w
        nx = g[:, 0] * wx + g[:, 3] * wy + g[:, 6] * wz
        ny = g[:, 1] * wx + g[:, 4] * wy + g[:, 7] * wz
        nz = g[:, 2] * wx + g[:, 5] * wy + g[:, 8] * wz
        inv = 1.0 / np.sqrt(nx * nx + ny * ny + nz * nz)
        return nx * inv, ny * inv, nz * inv

    # ------------------------------------------------------------------------------------------
    def draw_primitive(self, k: int, a: np.ndarray, b: np.ndarray, M: np.ndarray, round_r: float = 0.0) -> None:
        """Draw the affine capsule (ends ``a``, ``b`` (3,), map ``M`` (3, 3), camera frame metres; see
        :mod:`.body`) as primitive id ``k``. ``round_r > 0`` says ``M = I / round_r`` (faster path)."""
        if round_r > 0:
            half = np.full(3, round_r)
        else:
            half = np.linalg.norm(np.linalg.inv(M), axis=1)  # half extents of the ellipsoid M^-1 (unit ball)
        box = self.bbox(np.minimum(a, b) - half, np.maximum(a, b) + half)
        if box is None:
            return
        v0, v1, u0, u1 = box
        X = self.dx[None, u0:u1]
        Y = self.dy[v0:v1, None]
        if round_r > 0:  # work in camera units: radius r
            Ml = np.eye(3)
            al, bl, r2 = a, b, round_r * round_r
            dd = self.dd[v0:v1, u0:u1]
        else:  # work in the capsule's own space: radius 1, ray direction M d
            Ml = M
            al, bl, r2 = M @ a, M @ b, 1.0
            G = M.T @ M
            dd = (float(G[0, 0]) * X + 2.0 * (float(G[0, 1]) * Y + float(G[0, 2]))) * X + (
                (float(G[1, 1]) * Y + 2.0 * float(G[1, 2])) * Y + float(G[2, 2])
            )
        axis = bl - al
        L = float(np.linalg.norm(axis))

        def lin(v: np.ndarray) -> np.ndarray:  # (M d) . v for every pixel, v in the capsule's space
            w = Ml.T @ v
            return float(w[0]) * X + (float(w[1]) * Y + float(w[2]))

        aa, bb = float(al @ al), float(bl @ bl)
        da = lin(al)
        with np.errstate(invalid="ignore", divide="ignore"):
            if L < 1e-9:  # ellipsoid / sphere
                disc = da * da - dd * (aa - r2)
                hit = disc >= 0
                t = (da - np.sqrt(np.maximum(disc, 0.0))) / dd
            else:
                u = axis / L
                au = float(al @ u)
                du = lin(u)
                # infinite cylinder around the axis, ray from the origin: A t^2 + 2 B t + C = 0
                A = dd - du * du
                B = du * au - da
                C = aa - au * au - r2
                disc = B * B - A * C
                t_cyl = (-B - np.sqrt(np.maximum(disc, 0.0))) / A
                s = t_cyl * du - au  # where the ray enters the cylinder, along the axis
                side_a = s < 0
                inside = ~side_a & (s <= L)
                # otherwise the first hit is on the end cap of the side the ray entered
                dc = np.where(side_a, da, lin(bl))
                cc = np.where(side_a, aa, bb)
                disc2 = dc * dc - dd * (cc - r2)
                t_sph = (dc - np.sqrt(np.maximum(disc2, 0.0))) / dd
                hit = (disc >= 0) & (inside | (disc2 >= 0))
                t = np.where(inside, t_cyl, t_sph)
        self._remember(k, Ml, al, axis / L if L >= 1e-9 else np.zeros(3), L)
        self._commit(box, t, hit, k)

    def draw_body(self, geom: BodyGeometry, i: int = 0) -> None:
        """Clear, then draw every primitive of frame ``i`` of ``geom`` (camera frame)."""
        self.clear()
        for k in range(geom.a.shape[-2]):
            self.draw_primitive(k, geom.a[i, k], geom.b[i, k], geom.M[i, k], float(geom.round_r[k]))
