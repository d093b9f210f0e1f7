"""The bound on what the correction moves the TOOL by: ``compensate``'s
check, every cycle, of the tool point's displacement and the tool's
rotation that the correction it is about to command adds to the
reference (``--max-correction-mm``, ``--max-correction-deg``).

The per-joint clamp (``--saturation-deg``) does not bound the tool: at
the test start pose 0.5 deg on one joint moves the tool point 11-14 mm,
32 mm on all joints at once, while a deflection correction is a few
tenths of a mm (the paper's block: 0.4 mm).  A correction of centimetres
is a fault (a wrong model file, a sensor mounted or scaled wrong, a wrong
unit), not a deflection: the loop treats it as one (a log line when it
starts and ends, the correction ramps to zero, counted in summary.json).

How.  The tool Jacobian J (model/realtime.DeflectionPredictor's, the
compensator's own kinematics) at the arm's measured joints times the
correction c (model joints, rad): J c = (displacement m, rotation rad),
the first-order change of the commanded pose from its reference.  Not
forward kinematics of commanded against reference: two chains a cycle
(about 20 us each in plain Python) where the Jacobian is the one the
model's prediction has just computed at the same joints (a memo hit) and
J c is 36 multiply-adds (measured: ``python benchmarks/correction_bound_cost.py``).
The second-order rest is of the order of |c| (rad) of the result (a 5 mm
correction on a 1.5 m arm: 0.3 %; tests/test_correction_bound.py holds it
within 1 % of forward kinematics), and the Jacobian is taken again when the measured
joints have moved REFRESH_RAD from where it was taken (a stale one is
off by about that fraction): both far inside the bound's margin.

While the bound's fault lasts the correction shrinks toward zero in
proportion (every joint by the same factor, the largest by the rate limit
a cycle): J (s c) = s J c, so each step's tool displacement is below the
last one's, which was inside the bound; a target beyond the bound is never
sent.  The model still runs meanwhile (its wish is judged every cycle):
the fault ends when the correction is zero and the model's wish has been
inside the bound for ``clear_messages`` messages (compensate's
CLEAR_MESSAGES, 25, as a sequence fault's).  ``start_note``: the check
before the run (``hold_note``: at the hold pose, in the start's work).
"""

import math

# ASSUMPTION (the default of --max-correction-mm): 5 mm.  The largest
# deflection a correction should ever need: a process force of 1000 N
# (compensate's --max-jump-N: the force step its sensor guard still takes as
# physical, several times a milling cut's few hundred N; tests/cell_helpers
# .cutting_wrench: 400 N) in its worst direction deflects the IRB 6400 (the
# paper's arm, the library's stiffness: docs/assumptions.md) 4.9 mm at the
# block test's start pose (``start_note``; the x compliance over its machining
# workspace is 1.5-4.3 um/N, the paper's Table 2 2.5-4 um/N): rounded up, 5 mm.
# Over ten times the paper's block (0.4 mm), a sixth of what the 0.5 deg
# clamp allows (32 mm at that pose); a few mm off the path spoils a part but
# stays inside a fixture's clearance (tens of mm).  A softer arm (the library's
# KR 240: 7.2 mm, R-2000iC: 12.7 mm under 1000 N there) gets ``start_note``'s
# warning: set the bound from its own figure.
DEFAULT_MAX_CORRECTION_MM = 5.0
# ASSUMPTION (the default of --max-correction-deg): 0.5 deg.  The same 1000 N
# turns the IRB 6400's tool by 0.25 deg at that pose (``start_note``): twice
# it; one wrist joint's clamp (0.5 deg) alone reaches it, never more.
DEFAULT_MAX_CORRECTION_DEG = 0.5
# The Jacobian is taken again when a measured joint has moved this far (rad,
# 0.29 deg) from where it was taken: a stale Jacobian is off by about this fraction.
REFRESH_RAD = 0.005
# Rounding: a correction this close to the bound (m; rad) is inside it.
EPS_M = 1e-9
EPS_RAD = 1e-9


class CorrectionBound:
    """``excess(q, c)``: None when the correction ``c`` (model joints, rad)
    at the measured joints ``q`` (model joints, rad) moves the tool point at
    most ``max_mm`` and turns the tool at most ``max_deg``; else one line
    saying by how much.  Counts for summary.json (``summary``)."""

    def __init__(self, predictor, max_mm, max_deg):
        self.pred = predictor  # model/realtime.DeflectionPredictor (the compensator's, with its tool point)
        self.max_m, self.max_rad = float(max_mm) / 1e3, math.radians(float(max_deg))
        self.max_mm, self.max_deg = float(max_mm), float(max_deg)
        self._lim_m, self._lim_rad = self.max_m + EPS_M, self.max_rad + EPS_RAD
        self._q = None
        self._cols = None
        self.onsets = 0  # the bound's faults
        self.cycles = 0  # cycles the model's wish or the commanded correction was beyond it
        self.ok_cycles = 0  # consecutive cycles inside it (the fault's end)
        self.largest_mm = 0.0  # the largest tool displacement commanded (sent) in the run (mm)
        self.largest_deg = 0.0  # and rotation (deg)
        self.last = (0.0, 0.0)  # (m, rad) of the correction ``bounded`` returned last

    @classmethod
    def of(cls, compensator, settings):
        """The bound of a loop's ``settings`` (LoopSettings.max_correction_mm, _deg; None when both are
        infinite) on ``compensator``'s kinematics (model/compensator.Compensator: its predictor's tool point)."""
        if math.isinf(settings.max_correction_mm) and math.isinf(settings.max_correction_deg):
            return None
        model = getattr(compensator.model, "plain", compensator.model)  # (--mode preview: the plain chain's)
        return cls(model._pred, settings.max_correction_mm, settings.max_correction_deg)

    def displacement(self, q, c):
        """(|translation| m, |rotation| rad) of J(q) c."""
        p, R = self._q, REFRESH_RAD
        if p is None or (abs(q[0] - p[0]) > R or abs(q[1] - p[1]) > R or abs(q[2] - p[2]) > R
                         or abs(q[3] - p[3]) > R or abs(q[4] - p[4]) > R or abs(q[5] - p[5]) > R):
            self._q, self._cols = tuple(q), self.pred.jacobian_rows(q)
        (c0, c1, c2, c3, c4, c5), (j0, j1, j2, j3, j4, j5) = c, self._cols  # (unrolled: the real-time path)
        x = j0[0] * c0 + j1[0] * c1 + j2[0] * c2 + j3[0] * c3 + j4[0] * c4 + j5[0] * c5
        y = j0[1] * c0 + j1[1] * c1 + j2[1] * c2 + j3[1] * c3 + j4[1] * c4 + j5[1] * c5
        z = j0[2] * c0 + j1[2] * c1 + j2[2] * c2 + j3[2] * c3 + j4[2] * c4 + j5[2] * c5
        a = j0[3] * c0 + j1[3] * c1 + j2[3] * c2 + j3[3] * c3 + j4[3] * c4 + j5[3] * c5
        b = j0[4] * c0 + j1[4] * c1 + j2[4] * c2 + j3[4] * c3 + j4[4] * c4 + j5[4] * c5
        e = j0[5] * c0 + j1[5] * c1 + j2[5] * c2 + j3[5] * c3 + j4[5] * c4 + j5[5] * c5
        return math.sqrt(x * x + y * y + z * z), math.sqrt(a * a + b * b + e * e)

    def excess(self, q, c, what):
        """None, or why ``c`` (``what``: whose correction) is beyond the bound
        (its displacement kept in ``last``)."""
        d, r = self.last = self.displacement(q, c)
        if d <= self._lim_m and r <= self._lim_rad:  # (False for NaN)
            return None
        return (f"{what} moves the tool point {d * 1e3:.2f} mm and turns the tool {math.degrees(r):.3f} deg "
                f"(at most {self.max_mm:g} mm, --max-correction-mm, and {self.max_deg:g} deg, --max-correction-deg): "
                "not a deflection (a wrong model file, a sensor mounted or scaled wrong, a wrong unit?)")

    def sent(self):
        """Note the displacement of the correction ``bounded`` returned last,
        its target sent (for summary.json)."""
        d, r = self.last
        self.largest_mm = max(self.largest_mm, d * 1e3)
        self.largest_deg = max(self.largest_deg, math.degrees(r))

    def summary(self):
        return {"max_correction_mm": self.max_mm, "max_correction_deg": self.max_deg, "faults": self.onsets,
                "cycles_beyond": self.cycles, "largest_sent_mm": self.largest_mm, "largest_sent_deg": self.largest_deg}


def shrink(c, step):
    """``c`` (rad, 6) scaled toward zero so that its largest joint moves by
    at most ``step`` (rad): every joint by the same factor (the tool's
    displacement shrinks in proportion)."""
    big = max(abs(v) for v in c)
    if big <= step:
        return [0.0] * 6
    s = 1.0 - step / big
    return [v * s for v in c]


def bounded(loop, corr, step_dt_s, model_ran, clear_messages):
    """The loop's correction for this cycle (rad, model joints) within the
    bound: ``corr`` when it and the model's wish (``model_ran``: the model
    ran this cycle) are inside it; else the bound's fault (on, or kept) and
    the last sent correction shrunk toward zero at the rate limit over
    ``step_dt_s``.  The compensator's held correction follows."""
    b = loop.bound
    if b is None or loop.q is None:
        return corr
    why = b.excess(loop.q, loop.comp.dq, "the model's correction") if model_ran else None
    why = b.excess(loop.q, corr, "the correction") or why  # (the correction's last: ``last`` is its)
    if why:
        b.cycles += 1
        b.ok_cycles = 0
        if "bound" not in loop.faults:
            b.onsets += 1
            loop.fault_on("bound", f"correction bound: {why}")
    elif "bound" in loop.faults:
        zero = all(v == 0.0 for v in loop._corr_sent)
        b.ok_cycles = b.ok_cycles + 1 if zero and model_ran else 0
        if b.ok_cycles >= clear_messages:
            loop.fault_off("bound", f"correction bound: the model's correction inside it for {b.ok_cycles} "
                                    "messages and the correction at zero; compensating again")
            return corr
    if "bound" not in loop.faults:
        return corr
    rate = loop.s.rate_limit_rad_per_s
    out = shrink(loop._corr_sent, rate * step_dt_s)
    d, r = b.displacement(loop.q, out)
    if d > b.max_m or r > b.max_rad:  # (only when the arm has moved since: the Jacobian differs) to the bound
        s = min(b.max_m / d if d > b.max_m else 1.0, b.max_rad / r if r > b.max_rad else 1.0)
        out = [v * s for v in out]
        d, r = d * s, r * s
    b.last = (d, r)
    loop.comp.correction = list(out)
    return out


def start_note(predictor, q_rows_deg, to_model, force_N, max_mm, max_deg, what):
    """Before the run: the tool's deflection the model predicts under a
    process force of ``force_N`` (N, compensate's --max-jump-N: the largest
    force step its guard takes as physical) in the worst direction, at up to
    SAMPLES rows of the reference (controller deg, (N, 6); ``to_model``: their
    map to the model's radians; ``what``: its name; one row: a pose, the
    hold pose without a reference).  A warning line when it is beyond the bound (a cut that hard would
    be stopped as this fault), else None.  Not a refusal: the job's forces are
    not known before the cut (the worst direction of 1000 N is a bound, not a
    prediction); the bound itself stops a correction beyond it."""
    import numpy as np

    rows = np.unique(np.linspace(0, len(q_rows_deg) - 1, min(SAMPLES, len(q_rows_deg))).round().astype(int))
    q = dict(zip(rows.tolist(), np.asarray(to_model(np.asarray(q_rows_deg, dtype=float)[rows]), dtype=float)))
    C = np.diag(predictor.joint_compliance)
    worst = (0.0, 0.0, 0)
    for r in rows:
        J = predictor.jacobian(q[r])
        Ct = J @ C @ J.T  # the tool's compliance (m/N, rad/N; m/(N*m), rad/(N*m))
        d = float(np.linalg.norm(Ct[:3, :3], 2)) * force_N  # the largest displacement under force_N (m)
        rot = float(np.linalg.norm(Ct[3:, :3], 2)) * force_N  # and rotation (rad)
        if d * 1e3 / max_mm + math.degrees(rot) / max_deg > worst[0] * 1e3 / max_mm + math.degrees(worst[1]) / max_deg:
            worst = (d, rot, int(r))
    d, rot, r = worst
    if d * 1e3 <= max_mm and math.degrees(rot) <= max_deg:
        return None
    where = what if len(q_rows_deg) == 1 else f"{what}'s row {r + 1}"
    return (f"a process force of {force_N:g} N (--max-jump-N) in its worst direction deflects the tool "
            f"{d * 1e3:.2f} mm and {math.degrees(rot):.3f} deg at {where} by the model: beyond "
            f"--max-correction-mm {max_mm:g} / --max-correction-deg {max_deg:g}; a cut that hard would be stopped as a "
            "fault (the correction ramped to zero)")


SAMPLES = 12  # rows of a reference start_note looks at (evenly spaced, the first and last among them)


class _PlainKinematics:
    """``start_note``'s predictor beside the loop's thread: model/kinematics'
    Jacobian (the same convention), which keeps no memo; DeflectionPredictor's
    chain memo is shared by every predictor of the arm and has no lock, and
    the loop's thread uses it meanwhile."""

    def __init__(self, robot, k_Nm_per_rad):
        import numpy as np

        self.dh, self.tool_m = robot.dh, robot.payload.tool_point_m
        self.joint_compliance = 1.0 / np.asarray(k_Nm_per_rad, dtype=float)  # rad/(N*m)

    def jacobian(self, q_rad):
        from robstiff_drake.model import kinematics

        return kinematics.jacobian(self.dh, q_rad, self.tool_m)


def hold_note(robot, k_Nm_per_rad, q_deg, force_N, max_mm, max_deg):
    """``start_note`` at the hold pose (``q_deg``: the controller's first
    message, controller deg) without --reference or --job: a start job of
    cell/start_gate.py, run beside the loop's thread (which answers with zero
    correction meanwhile), so on plain kinematics (``_PlainKinematics``)."""
    import numpy as np

    return start_note(_PlainKinematics(robot, k_Nm_per_rad), [list(q_deg)],
                      lambda q: robot.joint_map.to_model(np.radians(q)), force_N, max_mm, max_deg,
                      "the hold pose (the controller's first message)")
