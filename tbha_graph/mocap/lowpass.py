"""Zero-phase Butterworth low-pass along time: the project's one implementation.

Second-order sections (``scipy.signal.butter(..., output="sos")``) run forwards and backwards
(``sosfiltfilt``): no lag, and the magnitude response is squared (the -3 dB point of the designed
filter becomes -6 dB). Used by ``filter.butterworth`` and by ``reconstruct.temporal_ray_sphere``'s
torso smoothing. ``scipy.signal`` is imported on first call (it costs about 0.6 s).
"""
from __future__ import annotations

import numpy as np


def butterworth_lowpass(x: np.ndarray, fps: float, cutoff: float, order: int = 4, padlen: int | None = None) -> np.ndarray:
    """Zero-phase low-pass of ``x`` ``(n_frames, ...)`` along axis 0; ``fps`` and ``cutoff`` in Hz.

    ``padlen``: samples of odd extension at each end (None: scipy's default for the filter); clips
    shorter than that are padded as much as they allow (``n_frames - 1``); a single frame is returned
    unchanged. Raises ``ValueError`` if ``cutoff >= fps / 2``.
    """
    from scipy.signal import butter, sosfiltfilt

    if cutoff >= fps / 2:
        raise ValueError(f"cutoff {cutoff} Hz must be below the Nyquist frequency {fps / 2} Hz")
    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] < 2:
        return x.copy()
    sos = butter(order, cutoff, btype="low", fs=fps, output="sos")
    if padlen is None:  # scipy's default, computed here so that it can be shortened for short clips
        padlen = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    return sosfiltfilt(sos, x, axis=0, padlen=min(padlen, x.shape[0] - 1))
