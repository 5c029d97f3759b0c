"""Gait measures on toe tracks: heights above the clip's own floor, support, lift, alternation,
step frequency and amplitude, the contact height, the root's height range. Pure numpy functions;
training's gait targets (data.gait_stats) and the evaluation protocol both read them.

Conventions: metres, Y up, frames at the data rate `fps`.
"""

from __future__ import annotations

import numpy as np

from motiongan_jax.motion import arrays

GAIT_FLOOR_PERCENTILE = 5.0  # the floor: this percentile of the lower toe's height over the clip
STEP_BAND_HZ = (0.4, 4.0)  # gait cycles per second considered by step_frequency_hz


def toe_heights(toes_world_Tx2x3, floor_percentile: float = GAIT_FLOOR_PERCENTILE) -> np.ndarray:
    """Heights (T, K) of the K toes above the clip's floor, the `floor_percentile` of the lower
    toe's height over the clip: robust to a few frames below it (noise, a stumble)."""
    toes = arrays.float_array(toes_world_Tx2x3, "toes_world_Tx2x3", 3, shape=(None, None, 3))
    p = float(floor_percentile)
    if not 0.0 <= p <= 100.0:
        raise ValueError(f"floor_percentile: must lie in [0, 100], got {floor_percentile}")
    y = toes[..., 1]
    return y - np.percentile(y.min(axis=1), p)


def support(heights_TxK, contact_height_m: float) -> float:
    """Share of frames in which the lowest toe is within `contact_height_m` of the floor
    (a walk always keeps a foot down; a hop or a float does not)."""
    h = arrays.float_array(heights_TxK, "heights_TxK", 2)
    return float(np.mean(h.min(axis=1) < arrays.positive(contact_height_m, "contact_height_m")))


def lower_foot_height(heights_TxK) -> float:
    """Mean height (metres) of the lower toe above the floor (real walks: millimetres)."""
    return float(np.mean(arrays.float_array(heights_TxK, "heights_TxK", 2).min(axis=1)))


def alternation(heights_Tx2) -> float:
    """−corr(left toe height, right toe height): positive when the feet lift in turn (a walk),
    negative when they move together (a hop, a glide that bobs). nan if a foot never moves."""
    h = arrays.float_array(heights_Tx2, "heights_Tx2", 2, shape=(None, 2), min_len=3)
    if np.ptp(h[:, 0]) == 0 or np.ptp(h[:, 1]) == 0:
        return float("nan")
    return float(-np.corrcoef(h[:, 0], h[:, 1])[0, 1])


def step_frequency_hz(heights_Tx2, fps: float, band_hz: tuple[float, float] = STEP_BAND_HZ) -> float:
    """Gait cycles per second (one left and one right step each): the dominant frequency of
    left − right toe height, which rises and falls once per cycle. The difference is detrended,
    Hann-windowed and zero-padded to 16x its length; the highest spectral peak within `band_hz`
    is refined by a parabola through its log magnitudes. nan if the difference is constant or the
    clip is shorter than one cycle of the band's lowest frequency."""
    h = arrays.float_array(heights_Tx2, "heights_Tx2", 2, shape=(None, 2), min_len=4)
    fps = arrays.positive(fps, "fps")
    lo, hi = float(band_hz[0]), float(band_hz[1])
    if not 0 < lo < hi:
        raise ValueError(f"band_hz: need 0 < low < high, got {band_hz}")
    n = h.shape[0]
    if n / fps < 1.0 / lo:
        return float("nan")
    d = h[:, 0] - h[:, 1]
    t = np.arange(n)
    d = d - np.polyval(np.polyfit(t, d, 1), t)
    if np.allclose(d, 0.0, atol=1e-9):
        return float("nan")
    nfft = 16 * n
    mag = np.abs(np.fft.rfft(d * np.hanning(n), nfft))
    freqs = np.fft.rfftfreq(nfft, 1.0 / fps)
    idx = np.flatnonzero((freqs >= lo) & (freqs <= min(hi, fps / 2)))
    if idx.size == 0:
        return float("nan")
    k = int(idx[np.argmax(mag[idx])])
    if 0 < k < len(mag) - 1 and min(mag[k - 1], mag[k], mag[k + 1]) > 0:
        a, b, c = np.log(mag[k - 1 : k + 2])
        denom = a - 2 * b + c
        k = k + (0.5 * (a - c) / denom if denom < 0 else 0.0)
    return float(k * fps / nfft)


def step_amplitude_m(heights_Tx2) -> float:
    """Standard deviation (metres) of left − right toe height: how high the steps lift."""
    h = arrays.float_array(heights_Tx2, "heights_Tx2", 2, shape=(None, 2))
    return float(np.std(h[:, 0] - h[:, 1]))


def height_range_m(root_Tx3) -> float:
    """Range (max − min, metres) of the root's height over a clip: a float or a drift shows as
    a range far beyond a walk's bounce."""
    return float(np.ptp(arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3))[:, 1]))


def contact_height_threshold(foot_heights_real_N, percentile: float = 10.0) -> float:
    """Contact height (metres): the given percentile of real foot heights (y), pooled over
    frames and feet (ravel a (T, K) array first), for `skate_ratio`."""
    heights = arrays.float_array(foot_heights_real_N, "foot_heights_real_N", 1)
    p = float(percentile)
    if not 0.0 <= p <= 100.0:
        raise ValueError(f"percentile: must lie in [0, 100], got {percentile}")
    return float(np.percentile(heights, p))


def _floor_path_length(p_Tx3: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(p_Tx3[:, [0, 2]], axis=0), axis=-1)))


def walking_speed_mps(root_Tx3, fps: float) -> float:
    """Mean walking speed (m/s): the root's floor path length over the clip's duration."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=2)
    return _floor_path_length(root) * arrays.positive(fps, "fps") / (root.shape[0] - 1)


def travel_speed_mps(root_Tx3, fps: float, cycle_hz: float) -> float:
    """Travel speed (m/s) with the body's sway taken out: the root's floor path averaged over one
    gait cycle (a moving average 1/`cycle_hz` long, which cancels the sway, bob and surge at every
    harmonic of the cycle), its length over its duration. Unlike a smoothing that pads the ends,
    it is not slowed at the clip's ends. nan if `cycle_hz` is nan or the clip is shorter than two
    cycles."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=2)
    fps = arrays.positive(fps, "fps")
    if not np.isfinite(cycle_hz) or cycle_hz <= 0:
        return float("nan")
    n = max(int(round(fps / cycle_hz)), 1)
    if root.shape[0] < 2 * n:
        return float("nan")
    kernel = np.ones(n) / n
    xz = np.stack([np.convolve(root[:, i], kernel, mode="valid") for i in (0, 2)], axis=1)
    return float(np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1)) * fps / (len(xz) - 1))


def distance_per_cycle_m(root_Tx3, heights_Tx2, fps: float) -> float:
    """Distance walked per gait cycle (metres; one left and one right step): walking speed over
    step frequency (`step_frequency_hz`). nan where the step frequency is."""
    return walking_speed_mps(root_Tx3, fps) / step_frequency_hz(heights_Tx2, fps)


def counted_gait_cycles(root_Tx3, heights_Tx2, fps: float, hysteresis: float = 0.3) -> dict:
    """Gait cycles counted, not read off a spectrum: the left − right toe height (its 2-second
    moving average removed) crosses from above +h to below −h and back, h = `hysteresis` × its
    std, twice per cycle. Returns {"cycles": half-cycles between the first and last crossing / 2,
    "distance_m": the root's floor path between them, "stride_m": distance per counted cycle,
    "frequency_hz": cycles per second between them}; nan values with fewer than 3 crossings."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=2)
    h = arrays.float_array(heights_Tx2, "heights_Tx2", 2, shape=(root.shape[0], 2), min_len=2)
    fps = arrays.positive(fps, "fps")
    d = h[:, 0] - h[:, 1]
    w = max(int(round(2.0 * fps)), 1)
    d = d - np.convolve(np.pad(d, (w // 2, w - 1 - w // 2), mode="edge"), np.ones(w) / w, mode="valid")
    thr = hysteresis * np.std(d)
    state, crossings = 0, []
    for t, v in enumerate(d):
        s = 1 if v > thr else (-1 if v < -thr else 0)
        if s and s != state:
            if state:
                crossings.append(t)
            state = s
    nan = {"cycles": float("nan"), "distance_m": float("nan"), "stride_m": float("nan"),
           "frequency_hz": float("nan")}
    if len(crossings) < 3:
        return nan
    a, b = crossings[0], crossings[-1]
    cycles = (len(crossings) - 1) / 2
    dist = _floor_path_length(root[a:b + 1])
    return {"cycles": cycles, "distance_m": dist, "stride_m": dist / cycles, "frequency_hz": cycles * fps / (b - a)}
