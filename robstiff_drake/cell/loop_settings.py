"""The compensator loop's settings (cell/compensate.CompensatorLoop):
periods, timeouts, the correction's rate limit and clamp, the sensor's
moment guard, its rate and start check, and the bound on the correction's
tool motion.

Every default is ``robstiff compensate``'s, taken from the one place that
defines it (cell/correction_bound.py's bound; ``default_max_jump_Nm``,
which the command uses too): a program that builds LoopSettings itself
gets the command's checks, and switches one off only by saying so
(``math.inf``).

Units: in each field's name (s, rad/s, deg, N*m, mm).
"""

import math
import numbers
from dataclasses import dataclass, replace

from robstiff_drake.cell.correction_bound import DEFAULT_MAX_CORRECTION_DEG, DEFAULT_MAX_CORRECTION_MM
from robstiff_drake.cell.sensor_checks import DEFAULT_START_TOLERANCE_N

# ASSUMPTION: without --max-jump-Nm (LoopSettings.max_jump_Nm None), a moment jump is refused beyond what a
# force jump of --max-jump-N makes at this lever (m) or at the tool point's distance from the sensor, whichever
# is longer.
MIN_LEVER_M = 0.1


def default_max_jump_Nm(max_jump_N, tool_m):
    """The moment guard's default (N*m): the force guard's ``max_jump_N`` (N)
    at the tool point's lever (``tool_m``, m, sensor frame; None: none), at
    least MIN_LEVER_M."""
    lever = math.sqrt(sum(float(v) * float(v) for v in tool_m)) if tool_m is not None else 0.0
    return float(max_jump_N) * max(lever, MIN_LEVER_M)


@dataclass
class LoopSettings:
    """The loop's settings.  Every default is ``robstiff compensate``'s (a
    library user who builds these gets the command's checks): no default
    switches a check off.  A check is switched off only explicitly
    (``max_correction_mm=math.inf, max_correction_deg=math.inf``: no bound
    on the correction's tool motion; ``max_jump_Nm=math.inf``: no moment
    guard); a bound that is not a number or not above zero is a ValueError."""

    period_s: float = 0.004
    sensor_timeout_s: float = 0.02  # 5 IRC5 cycles without a valid record
    feedback_timeout_s: float = 0.02
    egm_timeout_s: float = 0.1  # "no message" log line after this
    # (0, never, is no missing check: a silent controller is commanded nothing, it holds its last target; the
    # silence is a fault, logged, and the correction is ramped from zero when messages come again)
    idle_exit_s: float = 0.0  # end the run after this long without a message (0: never)
    duration_s: float = 0.0  # end the run after this long (0: never; as idle_exit_s: no check depends on it)
    rate_limit_rad_per_s: float = math.radians(5.0)  # (compensate's --rate-limit-deg-per-s 5)
    saturation_deg: float = 0.5  # (compensate's --saturation-deg)
    # a moment jumping more than this (N*m) from the last good sample is refused; None: compensate's default,
    # the compensator's max_jump_N at the tool point's lever (``default_max_jump_Nm``), taken by
    # the loop (before: inf, no moment guard for a library user)
    max_jump_Nm: float = None
    # the correction's tool motion (mm, deg) beyond which it is a fault (cell/correction_bound.py: compensate's
    # --max-correction-mm / --max-correction-deg defaults and why; before: inf, no bound for a library user)
    max_correction_mm: float = DEFAULT_MAX_CORRECTION_MM
    max_correction_deg: float = DEFAULT_MAX_CORRECTION_DEG
    # why the online correction is held at zero for the whole run (None: it is computed, the default): a
    # reference that already carries the deflection's correction (compensate's --reference-is-corrected) is
    # streamed as it is; every check still runs (working ranges, steps, the start gate, the bound, the sensor)
    correction_off: str = None
    # the sensor's record rate the force filter is designed for (Hz; compensate's --sensor-rate-hz): a stream
    # more than 20 % off it is a fault for the session (cell/sensor_checks.py)
    sensor_rate_hz: float = 1000.0
    # the most the start's reading may differ from the payload calibration's prediction (N; the moments' at the
    # tool's lever): beyond it a fault for the session (cell/sensor_checks.py: compensate's default and why)
    start_tolerance_N: float = DEFAULT_START_TOLERANCE_N

    def resolved(self, compensator, robot):
        """These settings with the defaults that depend on the compensator
        and the arm filled in (max_jump_Nm None: ``default_max_jump_Nm``);
        itself when there are none."""
        if self.max_jump_Nm is not None:
            return self
        return replace(self, max_jump_Nm=default_max_jump_Nm(compensator.max_jump_N, robot.payload.tool_point_m))

    def __post_init__(self):
        if self.correction_off is not None and not (isinstance(self.correction_off, str) and self.correction_off):
            raise ValueError(f"LoopSettings.correction_off = {self.correction_off!r}: None (the correction "
                             "computed) or the reason it is held at zero")
        for name in ("max_correction_mm", "max_correction_deg", "max_jump_Nm", "start_tolerance_N"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, numbers.Real) and v > 0):  # (False for NaN)
                raise ValueError(f"LoopSettings.{name} = {v!r}: a bound above zero (math.inf: no check)")
        v = self.sensor_rate_hz
        if not (isinstance(v, numbers.Real) and 0 < v < math.inf):
            raise ValueError(f"LoopSettings.sensor_rate_hz = {v!r}: the sensor's record rate, a finite number of Hz "
                             "above zero")
