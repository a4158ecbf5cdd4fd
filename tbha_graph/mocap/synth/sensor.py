"""What the camera adds after the optics: lens blur, exposure flicker, sensor noise (all deterministic).

Applied to BGR uint8 frames (H, W, 3). Noise is Gaussian with ``noise_sigma`` in 8-bit grey levels,
independent per pixel and channel. Drawing 0.9 M normal numbers per frame would cost more than the
rest of the rendering, so a bank of ``2 x H x W x 3`` draws is made once per video and each frame adds
a window of it at a random offset (a fresh offset per frame, from the seeded generator): every frame
sees i.i.d. Gaussian noise, and frame differences are noise of variance ``2 sigma^2`` as they should be.
The per-frame exposure gain is ``1 + N(0, exposure_jitter)``.
"""
from __future__ import annotations

import cv2
import numpy as np


class Sensor:
    """Turns a rendered frame into a camera frame. One instance per video; frames in order."""

    def __init__(self, height: int, width: int, seed: int, noise_sigma: float, exposure_jitter: float, optics_blur_px: float):
        self.shape = (int(height), int(width), 3)
        self.noise_sigma = float(noise_sigma)
        self.exposure_jitter = float(exposure_jitter)
        self.blur = float(optics_blur_px)
        self.rng = np.random.default_rng([int(seed), 1])
        self.size = int(np.prod(self.shape))
        self.bank = None
        if self.noise_sigma > 0:
            bank = self.rng.normal(0.0, self.noise_sigma, size=2 * self.size)
            self.bank = np.clip(np.rint(bank), -32767, 32767).astype(np.int16)

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        if self.blur > 0:
            frame = cv2.GaussianBlur(frame, (0, 0), self.blur)
        if self.exposure_jitter > 0:
            gain = 1.0 + self.exposure_jitter * float(self.rng.standard_normal())
            frame = cv2.convertScaleAbs(frame, alpha=gain)
        if self.bank is not None:
            off = int(self.rng.integers(0, self.size))
            noise = self.bank[off : off + self.size].reshape(self.shape)
            frame = cv2.add(frame, noise, dtype=cv2.CV_8U)
        return frame
