"""What a cut asks of the spindle: the torque about its axis and the power
it takes, from the cutting wrench on the tool.  A run whose forces imply
more than the spindle's rating is not physical, whatever the forces were
calibrated to.  Plain numpy."""

import numpy as np


def spindle_torque_Nm(wrench_base, tool_axis_base):
    """Torque (N*m) the cut puts on the spindle about its axis, (N,): the
    wrench's moment (base frame, about the tool point, which is on the axis)
    along the tool axis (unit vectors, base frame, (N, 3))."""
    w = np.asarray(wrench_base, dtype=float).reshape(-1, 6)
    a = np.asarray(tool_axis_base, dtype=float).reshape(-1, 3)
    return np.abs(np.einsum("ni,ni->n", w[:, 3:], a))


def spindle_power_W(torque_Nm, spindle_rpm):
    """Mechanical power (W) the cut takes from the spindle: torque x speed."""
    return np.asarray(torque_Nm, dtype=float) * spindle_rpm * 2.0 * np.pi / 60.0


def specific_energy_J_per_mm3(power_W, removal_mm3_per_s):
    """Specific cutting energy (J/mm^3): the spindle power per material
    removal rate.  Aluminium alloys take about 0.7-1.0 J/mm^3 at the chip
    thicknesses of face milling, steels 2-4 (e.g. Kalpakjian & Schmid,
    Manufacturing Engineering and Technology, table of specific energies)."""
    return np.asarray(power_W, dtype=float) / removal_mm3_per_s
