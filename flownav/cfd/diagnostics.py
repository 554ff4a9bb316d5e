"""Wake diagnostics: Strouhal number from spectra, force statistics, spanwise fluctuation
level, and the choice of a loopable time window."""

from __future__ import annotations

import math

import numpy as np

from flownav.errors import ConfigError


def dominant_frequency(signal: np.ndarray, dt: float) -> float:
    """Peak frequency of a uniformly sampled signal (Hann window, zero padding, parabolic peak)."""
    x = np.asarray(signal, dtype=np.float64)
    if len(x) < 8:
        raise ConfigError(f"need >= 8 samples for a spectrum, got {len(x)}; run longer")
    x = x - x.mean()
    n = 16 * len(x)
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x)), n=n))
    k = int(np.argmax(spec[1:])) + 1
    if 1 <= k < len(spec) - 1:  # parabolic interpolation on the log spectrum
        a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
        k = k + 0.5 * (a - c) / (a - 2 * b + c)
    return float(k / (n * dt))


def zero_crossing_frequency(signal: np.ndarray, dt: float) -> float:
    """Mean frequency from upward zero crossings of the mean-removed signal (interpolated)."""
    x = np.asarray(signal, dtype=np.float64)
    x = x - x.mean()
    i = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    if len(i) < 2:
        return float("nan")
    t = (i + x[i] / (x[i] - x[i + 1])) * dt
    return float((len(t) - 1) / (t[-1] - t[0]))


def force_stats(t: np.ndarray, cd: np.ndarray, cl: np.ndarray) -> dict:
    """Mean drag, rms and amplitude of lift, and the Strouhal number from the lift spectrum."""
    dt = float(np.median(np.diff(t)))
    return {
        "Cd_mean": float(np.mean(cd)),
        "Cd_rms_fluct": float(np.std(cd)),
        "Cl_rms": float(np.std(cl)),
        "St_lift_spectrum": dominant_frequency(cl, dt),
        "St_lift_zero_crossings": zero_crossing_frequency(cl, dt),
        "window": [float(t[0]), float(t[-1])],
    }


def rms_w(velocity: np.ndarray) -> float:
    """rms of the spanwise velocity w (units of U) over the given frames and points."""
    w = np.asarray(velocity[..., 2], dtype=np.float64)
    return float(np.sqrt(np.mean(w**2)))


def spanwise_wavelength(w: np.ndarray, dz: float) -> tuple[float, list[float]]:
    """Dominant spanwise wavelength of ``w[..., Nz]`` (periodic z), and energy shares of k >= 1."""
    spec = (np.abs(np.fft.rfft(np.asarray(w, dtype=np.float64), axis=-1)) ** 2).reshape(-1, w.shape[-1] // 2 + 1)
    energy = spec.mean(0)[1:]
    k = int(np.argmax(energy)) + 1
    return float(w.shape[-1] * dz / k), (energy / energy.sum()).round(4).tolist()


def best_loop_window(
    frames: np.ndarray, period_frames: float, min_periods: int = 3, max_frames: int | None = None
) -> tuple[int, int, dict]:
    """Window ``[start, start + T)`` of a whole number of shedding periods with the smallest seam.

    The loader plays frame ``T - 1`` then frame ``0`` again, so the ideal window has
    ``frames[start + T]`` equal to ``frames[start]``. Candidates: every start and every ``T``
    within one frame of ``n * period_frames`` (``n >= min_periods``, ``T <= max_frames``).
    Returns ``(start, T, info)``; ``info['seam_rel']`` is |u[start+T] - u[start]| relative to
    the mean frame-to-frame change (1 = the seam is as smooth as an ordinary step).
    """
    f = np.asarray(frames, dtype=np.float32)
    n_frames = len(f)
    max_frames = n_frames - 1 if max_frames is None else min(max_frames, n_frames - 1)
    step = float(np.sqrt(np.mean((f[1:] - f[:-1]) ** 2)))
    best = None
    n = min_periods
    while math.floor(n * period_frames) <= max_frames:
        for T in sorted({math.floor(n * period_frames), math.ceil(n * period_frames)}):
            if T > max_frames:
                continue
            for s in range(0, n_frames - T):
                jump = float(np.sqrt(np.mean((f[s + T] - f[s]) ** 2)))
                if best is None or jump < best[0]:
                    best = (jump, s, T, n)
        n += 1
    if best is None:
        raise ConfigError(
            f"{n_frames} frames (max {max_frames} stored) do not hold {min_periods} shedding "
            f"periods of {period_frames:.1f} frames plus one; record longer or store fewer "
            "frames per period"
        )
    jump, s, T, n = best
    return s, T, {"periods": n, "seam_rel": jump / step, "seam_abs_rms": jump}
