"""Signal processing of joint logs as dynamic identification does it: zero-phase low-pass filtering,
differentiation on the recorded clock, decimation of regressor and torques together.

Positions are low-passed with a Butterworth filter run forwards and backwards (`scipy.signal.sosfiltfilt`:
no phase lag, so velocity and acceleration stay aligned with the torques), then differentiated twice on
the recorded times (`np.gradient`, second order, uneven steps allowed).  Pure functions of arrays (T, J);
SI units: s, Hz, rad / m and their derivatives.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

ORDER = 4  # Butterworth order (FIGAROH's and the field's usual choice)


def sample_rate(t: np.ndarray) -> float:
    """The recording's rate, Hz: 1 / the median step of the times `t` (s)."""
    return float(1.0 / np.median(np.diff(np.asarray(t, float))))


def lowpass(x: np.ndarray, fs: float, cutoff: float, order: int = ORDER) -> np.ndarray:
    """`x` (T, …) low-passed at `cutoff` Hz (zero phase, along axis 0); unchanged when the cut-off is at
    or above Nyquist."""
    x = np.asarray(x, float)
    if cutoff >= 0.5 * fs or x.shape[0] < 3 * (2 * order + 1):
        return x.copy()
    return sosfiltfilt(butter(order, cutoff, fs=fs, output="sos"), x, axis=0)


def derivatives(t: np.ndarray, q: np.ndarray, cutoff: float, order: int = ORDER) -> tuple[np.ndarray, ...]:
    """(q̃, q̇, q̈) (T, J): positions low-passed at `cutoff` Hz and their first and second time derivatives
    on the recorded clock `t` (s)."""
    t = np.asarray(t, float)
    qf = lowpass(q, sample_rate(t), cutoff, order)
    v = np.gradient(qf, t, axis=0, edge_order=2)
    return qf, v, np.gradient(v, t, axis=0, edge_order=2)


def decimation_rows(n: int, factor: int, offset: int = 0) -> np.ndarray:
    """Row indices keeping one sample in `factor` (after a low-pass below the new Nyquist rate, this is
    decimation: regressor rows and torques are taken at the same rows)."""
    return np.arange(offset % max(factor, 1), n, max(factor, 1))


MODEL_RATE_HZ = 500.0  # the highest rate identification works at: 30× its highest cut-off (16 Hz)


def decimation_factor(t: np.ndarray, max_rate: float = MODEL_RATE_HZ) -> int:
    """How many recorded samples make one modelled sample: 1 up to `max_rate` Hz, else ⌊rate / max_rate⌋."""
    return max(1, int(sample_rate(t) // max_rate)) if np.size(t) > 1 else 1


def decimate(t: np.ndarray, q: np.ndarray, tau: np.ndarray, factor: int) -> tuple[np.ndarray, ...]:
    """(t, q, τ) at one sample in `factor`: positions and torques through the same zero-phase anti-alias
    low-pass (Butterworth at 0.4 × the new rate, below its Nyquist rate), then taken at the same rows — a
    fast drive log (kHz) kept whole in what a rigid-body model can predict, its noise averaged rather than
    discarded."""
    if factor <= 1:
        return t, q, tau
    fs = sample_rate(t)
    rows = decimation_rows(np.shape(t)[0], factor)
    cut = 0.4 * fs / factor
    return np.asarray(t, float)[rows], lowpass(q, fs, cut)[rows], lowpass(tau, fs, cut)[rows]
