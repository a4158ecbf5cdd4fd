"""Surface colour of the rendered body: suit / hair / shoe albedo, coloured patches, Lambert + Blinn-Phong.

Colours are sRGB in [0, 1]; lighting is computed in linear light with a gamma-2 approximation
(linear = sRGB^2, sRGB = sqrt(linear)), which is cheap and close to the sRGB curve. Directions are
unit vectors; the key light direction is given in the world frame (pointing *towards* the light) and
turned into the camera frame once per video. A weak fill light sits at the camera.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .body import MATERIAL_HAIR, N_PRIMITIVES, PATCH_ALLOWED, PRIMITIVE_MATERIAL
from .raster import Raster

HAIR_RGB = (0.16, 0.13, 0.12)  # the dark head (hair / hood): the seed's "black patch" of the head
SHOE_RGB = (0.80, 0.80, 0.82)


def _candidates() -> np.ndarray:
    """(N_PRIMITIVES, 4) int: the patches that may lie on each primitive, padded with 15 ("no patch")."""
    width = max(4, int(PATCH_ALLOWED.sum(axis=0).max()))
    out = np.full((N_PRIMITIVES, width), PATCH_ALLOWED.shape[0], dtype=np.int64)
    for k in range(N_PRIMITIVES):
        ps = np.flatnonzero(PATCH_ALLOWED[:, k])
        out[k, : ps.size] = ps
    return out


_CANDIDATES = _candidates()


class Lighting(BaseModel):
    """Key light (directional) + camera fill + ambient, and the suit's specular sheen."""

    model_config = ConfigDict(extra="forbid")

    direction: tuple[float, float, float] = Field(
        (0.45, 0.8, 0.75), description="world direction towards the key light (normalised)"
    )
    key: float = Field(0.85, ge=0, le=4, description="key light intensity")
    fill: float = Field(0.2, ge=0, le=4, description="fill light at the camera, intensity")
    ambient: float = Field(0.22, ge=0, le=2, description="ambient light intensity")
    specular: float = Field(0.35, ge=0, le=4, description="specular highlight strength of the suit fabric")
    shininess: float = Field(28.0, gt=0, le=1000, description="Blinn-Phong exponent (higher = smaller highlight)")

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if float(np.linalg.norm(v)) < 1e-9:
            raise ValueError("the key light direction must not be the zero vector")
        return v


def material_albedo(suit_rgb: np.ndarray) -> np.ndarray:
    """Linear albedo (N_PRIMITIVES, 3) of each primitive from its material."""
    mats = np.stack([np.asarray(suit_rgb, dtype=np.float64), np.array(HAIR_RGB), np.array(SHOE_RGB)])
    return (mats[PRIMITIVE_MATERIAL] ** 2).astype(np.float32)


class Shader:
    """Shades the body pixels of a :class:`Raster` into a BGR uint8 image."""

    def __init__(self, raster: Raster, light: Lighting, R_world_to_cam: np.ndarray, suit_rgb, patch_rgb, patch_radius: float):
        self.raster = raster
        self.light = light
        d = np.asarray(R_world_to_cam, dtype=np.float64) @ np.asarray(light.direction, dtype=np.float64)
        self.L = (d / np.linalg.norm(d)).astype(np.float32)
        self.albedo_lut = material_albedo(suit_rgb)
        self.spec_lut = np.where(PRIMITIVE_MATERIAL == MATERIAL_HAIR, 0.15, 1.0).astype(np.float32)
        lin = np.asarray(patch_rgb, dtype=np.float64) ** 2
        self.patch_lin = np.concatenate([lin, np.zeros((1, 3))]).astype(np.float32)  # row 15: "no patch"
        self.patch_radius = float(patch_radius)

    def shade_into(self, image: np.ndarray, patch_cam: np.ndarray) -> None:
        """Overwrite the body pixels of ``image`` (H, W, 3) BGR uint8 with the shaded body; ``patch_cam``
        (15, 3) patch centres, camera frame metres. Per-pixel work on component arrays of shape (N,)."""
        r = self.raster
        if r.region is None:
            return
        v0, v1, u0, u1 = r.region
        iv, iu = np.nonzero(r.prim[v0:v1, u0:u1] >= 0)
        gv, gu = iv + v0, iu + u0
        ids = r.prim[gv, gu]
        nx, ny, nz = r.normals(gv, gu)
        rx, ry = r.dx[gu], r.dy[gv]
        z = r.depth[gv, gu]
        px, py = rx * z, ry * z
        # albedo: material, then the nearest patch allowed on this primitive, anti-aliased over a pixel
        a = self.albedo_lut[ids]
        C = np.concatenate([patch_cam, [[1e6, 1e6, 1e6]]]).astype(np.float32)  # row 15: "no patch"
        cand = _CANDIDATES[ids]  # (N, 4) patch indices allowed on each pixel's primitive
        d2 = (px[:, None] - C[cand, 0]) ** 2 + (py[:, None] - C[cand, 1]) ** 2 + (z[:, None] - C[cand, 2]) ** 2
        j = np.argmin(d2, axis=1)
        rows = np.arange(j.size)
        near = cand[rows, j]
        dist = np.sqrt(d2[rows, j])
        edge = np.maximum(C[:, 2] / np.float32(r.K[0, 0]), np.float32(1e-4))  # one pixel's footprint, metres
        w = np.clip((np.float32(self.patch_radius) - dist) / edge[near] + np.float32(0.5), 0.0, 1.0)
        a += w[:, None] * (self.patch_lin[near] - a)
        # light: key (Lambert + Blinn-Phong), fill at the camera, ambient
        Lx, Ly, Lz = (np.float32(c) for c in self.L)
        inv = -1.0 / np.sqrt(r.dd[gv, gu])
        vx, vy, vz = rx * inv, ry * inv, inv
        ndl = np.maximum(nx * Lx + ny * Ly + nz * Lz, 0.0)
        ndv = np.maximum(nx * vx + ny * vy + nz * vz, 0.0)
        hx, hy, hz = vx + Lx, vy + Ly, vz + Lz
        ndh = (nx * hx + ny * hy + nz * hz) / np.sqrt(hx * hx + hy * hy + hz * hz)
        lt = self.light
        spec = np.maximum(ndh, 0.0) ** np.float32(lt.shininess)
        spec *= (ndl > 0) * self.spec_lut[ids] * np.float32(lt.specular * lt.key)
        diffuse = np.float32(lt.ambient) + np.float32(lt.key) * ndl + np.float32(lt.fill) * ndv
        lin = a * diffuse[:, None] + spec[:, None]
        srgb = np.sqrt(np.clip(lin, 0.0, 1.0)) * np.float32(255.0) + np.float32(0.5)
        image[gv, gu] = srgb[:, ::-1].astype(np.uint8)
