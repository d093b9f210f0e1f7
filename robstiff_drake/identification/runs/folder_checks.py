"""Is a run folder what it claims to be?  Checks of a run's cell files
(identification/runs/files.py) against each other and against the robot,
before `robstiff diagnose-run` traces anything, so that a log in other units
or of another robot is one line naming the file, not a confident cause:

* ``wrench_units``: the wrist sensor's raw force is mostly the payload's
  weight (the compensator.yaml's payload_calibration.mass_kg); a median far
  below or above it is a log in kN or mN, a moment far above the weight's
  lever is one in N*mm;
* ``robot_matches``: the logged joint angles lie inside the robot's working
  ranges, and the tool path they give (forward kinematics of the robot with
  the settings' tool point) passes over the scanned face at its nominal
  height.

Plain numpy and scipy; no Drake.
"""

import numpy as np
from scipy.spatial import cKDTree

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs.tables import MIN_ROWS, SCAN
from robstiff_drake.model import kinematics as kin

GRAVITY_M_PER_S2 = 9.81
# The sensor's raw force magnitude against the payload's weight: the cut
# adds a few hundred N at most and the bias a few N, so the median is
# within a factor of a few of the weight; a factor of 20 either way is
# another unit (kN: 1/1000, mN: 1000).
FORCE_UNIT_FACTOR = 20.0
# The moment about the sensor origin is at most the weight times the
# payload's centre-of-mass distance plus the cut's moment; 30 times that is
# N*mm (1000) rather than N*m.  Not judged for a centre of mass within 10 mm.
MOMENT_UNIT_FACTOR = 30.0
MIN_COM_LEVER_M = 0.01
# The logged tool path's height over the scanned face against the face's
# nominal height (mm): the arm's deflection and a set-up offset are a
# millimetre or two (diagnose-run's setup_offset is bounded at 1 mm);
# 10 mm is another robot's kinematics or another cut.
MAX_FACE_HEIGHT_MISMATCH_MM = 10.0


def wrench_units(wrench, settings):
    """Refuse (InputError) a wrench log whose forces or moments are in
    another unit than N and N*m (see the module docstring)."""
    w = wrench.wrench[np.all(np.isfinite(wrench.wrench), axis=1)]
    if not len(w):
        return
    mass = float(settings.payload.get("mass_kg", 0.0))
    weight = mass * GRAVITY_M_PER_S2
    if weight <= 0:
        return
    f = float(np.median(np.linalg.norm(w[:, :3], axis=1)))
    if f < weight / FORCE_UNIT_FACTOR or f > weight * FORCE_UNIT_FACTOR:
        unit = "kN" if f < weight / FORCE_UNIT_FACTOR else "mN (or the payload's mass is wrong)"
        raise InputError(f"{wrench.path}: the force readings are {f:.3g} N (median magnitude), {f / weight:.3g} times "
                         f"the payload's weight ({weight:.0f} N, {mass:g} kg in {settings.path}): the log looks like "
                         f"{unit}; the wrench log is in N and N*m")
    lever = float(np.linalg.norm(settings.payload.get("com_mm", [0, 0, 0]))) / 1e3
    if lever >= MIN_COM_LEVER_M:
        m = float(np.median(np.linalg.norm(w[:, 3:], axis=1)))
        if m > MOMENT_UNIT_FACTOR * weight * lever:
            raise InputError(f"{wrench.path}: the moment readings are {m:.3g} N*m (median magnitude), "
                             f"{m / (weight * lever):.3g} times what the payload's weight exerts "
                             f"({weight * lever:.3g} N*m): the log looks like N*mm; the wrench log is in N*m")


def robot_matches(files, robot):
    """Refuse (InputError) a run whose joint log is not of ``robot``: angles
    outside its working ranges, or a tool path (its forward kinematics with
    the settings' tool point) that does not pass over the scan."""
    joints, settings, scan = files.joints, files.settings, files.scan
    named = f"{settings.path} names robot {settings.robot or robot.name!r}"
    lo, hi = np.rad2deg(robot.q_lower_rad), np.rad2deg(robot.q_upper_rad)
    bad = (joints.q_deg < lo - 1e-6) | (joints.q_deg > hi + 1e-6)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"{joints.path}: row {i + 1}: q{j + 1} = {joints.q_deg[i, j]:g} deg is outside "
                         f"{robot.name}'s working range [{lo[j]:g}, {hi[j]:g}] deg: the run is not of this robot "
                         f"({named})")
    tool_m = np.asarray(settings.tool_point_mm, dtype=float) / 1e3
    p_mm = kin.tool_position(robot.dh, robot.joint_rad(joints.q_deg - joints.correction_deg), tool_m) * 1e3
    radius = settings.cutter_diameter_mm / 2.0
    dist, nearest = cKDTree(p_mm[:, :2]).query(np.column_stack([scan.x_mm, scan.y_mm]),
                                               distance_upper_bound=radius)
    under = np.isfinite(dist)
    if under.sum() < MIN_ROWS[SCAN]:
        far = float(np.min(np.linalg.norm(p_mm[:, :2] - [np.median(scan.x_mm), np.median(scan.y_mm)], axis=1)))
        raise InputError(f"{joints.path}: the tool path of {robot.name} for these joint angles passes over "
                         f"{int(under.sum())} of the scan's points (it comes {far:.0f} mm from the scan's middle at "
                         f"best): the run is not of this robot, or the scan not of this cut ({named})")
    dz = float(np.median(p_mm[nearest[under], 2] - scan.nominal_mm[under]))
    if abs(dz) > MAX_FACE_HEIGHT_MISMATCH_MM:
        raise InputError(f"{joints.path}: the tool path of {robot.name} for these joint angles runs {dz:+.0f} mm "
                         f"from the scanned face's nominal height (at most {MAX_FACE_HEIGHT_MISMATCH_MM:g} mm): the "
                         f"run is not of this robot, or the scan not of this cut ({named})")


def check_run(files, robot):
    """Every check of this module on a loaded run folder (RunFiles)."""
    if files.wrench is not None:
        wrench_units(files.wrench, files.settings)
    if files.joints is not None:
        robot_matches(files, robot)

