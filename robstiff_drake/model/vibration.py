"""The tool's vibration in a run, from what any run logs (the tool point
along the run and when the cutter was in the material): how large it was,
at what frequency, and where it started growing (chatter found in the
run, not predicted).  Plain numpy; the definitions are those of
studies/regenerative_chatter.py (which imports them from here):

* the vibration: the tool point's in-plane motion (um: in the plane normal
  to the spindle axis, base x and y for a spindle-down tool; the axial
  motion apart, ``axial_um``) off its centred MEAN_WINDOW_S (20 ms) mean:
  the arm's low modes (4-15 Hz) and the path's ramps leave it, of an
  oscillation at 36 Hz about 68 % stays, at 40-70 Hz 77-120 % (so the
  amplitudes are this measure's, as the study's, not the sine's own);
* its envelope: the largest |vibration| (either axis) in each ENVELOPE_S
  (10 ms) window;
* the sustained amplitude (um): the largest running median of the
  envelope over SUSTAIN_S (0.1 s, 10 windows) within the cut (first to
  last sample in the material), so that a cut's entry transient (tens of
  ms) does not count and a limit cycle or a steady ripple does;
* its frequency (Hz): the largest peak of the in-plane spectrum between
  BAND_HZ over FREQUENCY_S (0.2 s) centred where the sustained amplitude
  is largest;
* the quiet level (um): the envelope's median over QUIET_S (0.3-0.8 s)
  after the cut's entry (a cut shorter than that: over its first half);
* the onset: the first envelope window from which the vibration stays
  above 3 times the quiet level (at least QUIET_FLOOR_UM, 1 um) until it reaches 10 times it, reported
  only when the sustained amplitude reaches 10 times the quiet level (a
  growth, not one spike); its time (s), the tool point there (mm) and the
  growth (1/s, least squares on the envelope's log from the onset to
  there, at least 3 windows).
"""

import math

import numpy as np

MEAN_WINDOW_S = 0.02  # the vibration: off its centred mean over this
ENVELOPE_S = 0.01  # the envelope's window
SUSTAIN_S = 0.1  # the sustained amplitude: the envelope's running median over this
FREQUENCY_S = 0.2  # the frequency: the spectrum over this, around the largest sustained amplitude
QUIET_S = (0.3, 0.8)  # the quiet level: after the cut's entry
BAND_HZ = (15.0, 180.0)  # the frequencies looked at (below: the arm's low modes the mean passes)
ONSET_ABOVE, ONSET_REACH = 3.0, 10.0  # the onset: stays above 3 x quiet until it reaches 10 x quiet
QUIET_FLOOR_UM = 1.0  # the onset's multiples taken of at least this (a "growth" from a sub-micrometre level, as the
# revolution-averaged plant's, is round-off and ringing, not chatter; the runout alone gives 14-16 um)


def moving_mean(t, v, window_s):
    """v's (n,) centred mean over ``window_s`` (NaN where the window leaves the record); t uniform (s).  The
    window holds an odd number of samples, so that it is centred on the sample (an even one is half a sample
    late: at 2 ms and 20 mm/s a 20 um offset of a steady feed)."""
    k = max(1, int(round(window_s / (t[1] - t[0]))))
    k += 1 - k % 2
    out = np.full(len(v), np.nan)
    if len(v) < k:
        return out
    c = np.concatenate(([0.0], np.cumsum(v)))
    out[k // 2:k // 2 + len(v) - k + 1] = (c[k:] - c[:-k]) / k
    return out


def off_mean(t, v, window_s=MEAN_WINDOW_S):
    """v off its centred ``window_s`` mean (NaN at the record's ends)."""
    return v - moving_mean(t, v, window_s)


def envelope(t, v):
    """(window start times s, largest |v| in each ENVELOPE_S window); v (n,) or (n, k)."""
    v = np.asarray(v, dtype=float).reshape(len(v), -1)
    dt = t[1] - t[0]
    n = max(1, int(round(ENVELOPE_S / dt)))
    m = len(v) // n
    a = np.abs(v[:m * n]).reshape(m, n, -1).max(axis=(1, 2))
    return t[:m * n:n], a


def peak_hz(t, v, band_hz=BAND_HZ):
    """The frequency (Hz) of v's (n, k) largest spectral peak within ``band_hz`` (Hanning window, zero-padded
    16 times; the band's top kept below 0.45 of the sampling rate); NaN when the band holds none."""
    v = np.asarray(v, dtype=float).reshape(len(v), -1)
    if len(v) < 4:
        return math.nan
    dt = t[1] - t[0]
    y = (v - v.mean(axis=0)) * np.hanning(len(v))[:, None]
    spec = np.abs(np.fft.rfft(y, 16 * len(v), axis=0)).sum(axis=1)
    f = np.fft.rfftfreq(16 * len(v), dt)
    band = (f > band_hz[0]) & (f < min(band_hz[1], 0.45 / dt))
    return float(f[band][np.argmax(spec[band])]) if band.any() else math.nan


SPINDLE_DOWN = (0.0, 0.0, -1.0)  # the spindle axis (base frame) when none is given: a spindle-down tool


def plane_axes(axis):
    """(u1, u2, a), each (n, 3) or (3,): the unit spindle axis ``a`` (base frame; (3,) or (n, 3), one per
    sample) and two unit vectors spanning the plane normal to it: u1 base x projected onto that plane (base y's
    where the axis is within 30 deg of x), u2 = a x u1.  For a spindle-down axis u1, u2 are base x and -y
    exactly (so the in-plane figures are base x and y's, to the bit)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    ex, ey = np.eye(3)[0], np.eye(3)[1]
    ref = np.where((np.abs(a[..., :1]) > 0.866), ey, ex)  # (cos 30 deg: x too close to the axis)
    u1 = ref - np.sum(ref * a, axis=-1, keepdims=True) * a
    u1 = u1 / np.linalg.norm(u1, axis=-1, keepdims=True)
    return u1, np.cross(a, u1), a


def off_mean_m(t, p_m):
    """The tool point's (n, 3 m) motion off its MEAN_WINDOW_S mean, each base axis (n, 3 m; 0 at the record's
    ends, where the mean is not defined)."""
    return np.nan_to_num(np.stack([off_mean(t, p_m[:, i]) for i in range(3)], axis=1))


def in_plane_um(t, p_m, axis=SPINDLE_DOWN):
    """The tool point's (n, 3 m) in-plane vibration (n, 2 um): its motion off its MEAN_WINDOW_S mean projected
    on the plane normal to the spindle ``axis`` (base frame, (3,) or (n, 3) per sample; plane_axes): base x and y
    for a spindle-down tool.  (The small motion is projected, not the position: a per-sample axis turning by a
    milliradian turns a metre of position by a millimetre.)"""
    d = off_mean_m(t, p_m)
    u1, u2, _ = plane_axes(axis)
    return np.stack([np.sum(d * u1, axis=-1), np.sum(d * u2, axis=-1)], axis=1) * 1e6


def axial_um(t, p_m, axis=SPINDLE_DOWN):
    """The tool point's (n, 3 m) vibration along the spindle ``axis`` (n, um; as in_plane_um)."""
    _, _, a = plane_axes(axis)
    return np.sum(off_mean_m(t, p_m) * a, axis=-1) * 1e6


def running_median(a, n):
    """The median of each n consecutive values of a (len(a) - n + 1 of them; a's median when shorter)."""
    if len(a) <= n:
        return np.array([np.median(a)]) if len(a) else np.zeros(0)
    return np.median(np.lib.stride_tricks.sliding_window_view(a, n), axis=1)


def run_vibration(t, p_m, in_cut, axis=SPINDLE_DOWN):
    """The tool's vibration during the cut (the module's definitions) from the
    run's uniformly sampled times ``t`` (n, s), tool points ``p_m`` (n, 3 m),
    whether the cutter was in the material ``in_cut`` (n, bool) and the
    spindle ``axis`` (base frame, (3,) or (n, 3) per sample; default
    spindle-down).  Returns a dict: amplitude_um (the sustained amplitude
    in the plane normal to the axis), axial_um (the same measure along
    it), spindle_axis (its mean over the cut, unit), frequency_hz,
    quiet_um, onset_t_s, onset_mm ([x, y, z] of the tool point there) and
    growth_per_s (each None when it does not grow), cut_s ([first, last]
    time in the material); None when the run never cut."""
    t = np.asarray(t, dtype=float)
    p_m = np.asarray(p_m, dtype=float)
    idx = np.flatnonzero(np.asarray(in_cut, dtype=bool))
    if len(t) < 3 or idx.size == 0:
        return None
    t0, t1 = t[idx[0]], t[idx[-1]]
    xy = in_plane_um(t, p_m, axis)
    te, a = envelope(t, xy)
    cut = (te >= t0) & (te + ENVELOPE_S <= t1)
    if not cut.any():
        cut = (te + ENVELOPE_S > t0) & (te <= t1)
    tc, ac = te[cut], a[cut]
    n_sus = max(1, int(round(SUSTAIN_S / ENVELOPE_S)))
    sus = running_median(ac, n_sus)
    k = int(np.argmax(sus))
    amp = float(sus[k])
    t_mid = tc[min(k + n_sus // 2, len(tc) - 1)] if len(ac) > n_sus else 0.5 * (t0 + t1)
    w = (t >= max(t0, t_mid - FREQUENCY_S / 2)) & (t < min(t1, t_mid + FREQUENCY_S / 2))
    _, a_ax = envelope(t, axial_um(t, p_m, axis))
    ax = np.broadcast_to(plane_axes(axis)[2], p_m.shape)[idx].mean(axis=0)
    out = {"amplitude_um": amp, "axial_um": float(running_median(a_ax[cut], n_sus).max()),
           "spindle_axis": [float(v) for v in ax / np.linalg.norm(ax)], "frequency_hz": peak_hz(t[w], xy[w]),
           "quiet_um": None, "onset_t_s": None, "onset_mm": None, "growth_per_s": None, "cut_s": [float(t0), float(t1)]}
    if math.isnan(out["frequency_hz"]):
        out["frequency_hz"] = None
    q = (tc >= t0 + QUIET_S[0]) & (tc < t0 + QUIET_S[1])
    if not q.any():  # a short cut: its first half
        q = tc < 0.5 * (t0 + t1)
    if not q.any():
        return out
    quiet = float(np.median(ac[q]))
    out["quiet_um"] = quiet
    after = tc >= (t0 + QUIET_S[1] if tc[-1] > t0 + QUIET_S[1] else tc[q][-1])
    # a growth, not one spike: the first median window (of n_sus envelope windows, starting at its index in ``sus``)
    # whose median reaches ONSET_REACH x quiet, after the quiet span; in it the first window that reaches it
    quiet = max(quiet, QUIET_FLOOR_UM)
    grown = [i for i in np.flatnonzero(sus >= ONSET_REACH * quiet) if after[i]]
    if not grown:
        return out
    reach = grown[0] + np.flatnonzero(ac[grown[0]:grown[0] + n_sus] >= ONSET_REACH * quiet)
    if not reach.size:
        return out
    above = ac > ONSET_ABOVE * quiet
    j = int(reach[0])
    while j > 0 and above[j - 1]:
        j -= 1
    t_on = float(tc[j])
    m = (tc >= t_on) & (tc <= max(tc[reach[0]], t_on + 2.5 * ENVELOPE_S))  # (at least 3 windows)
    g = float(np.polyfit(tc[m], np.log(np.maximum(ac[m], 1e-12)), 1)[0]) if m.sum() >= 2 else math.nan
    out.update(onset_t_s=t_on, onset_mm=[float(np.interp(t_on, t, p_m[:, i]) * 1e3) for i in range(3)],
               growth_per_s=None if math.isnan(g) else g)
    return out
