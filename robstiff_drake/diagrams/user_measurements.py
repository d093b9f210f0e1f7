"""What the preview compensator knows of the arm and the cell when its
model is "identified": only what a user measures (model.identification's
sizes, each drawn from its seed; "exact"/0 for the bound):

- the links' inertias: the robot file's, each mass and inertia off by a
  uniform draw within +-inertia_error (CAD or catalogue values);
- the damping: a modal test on the station with the drives on (hammer
  blows on the tool in x, y, z, the response fitted by ERA:
  identification/stiffness/modes.py), each fitted ratio given to the preview's
  mode nearest in frequency (what a user's test finds is the drives-closed
  damping; the modes it misses take the median of those it found);
- the tool point: from a TCP calibration, off by tcp_error_mm (1 sigma
  per axis, flange frame);
- the workpiece's top: from a touch probe, off by probe_error_mm (1 sigma,
  one offset for the part: the probe's touch-off).

None of these reads the plant's own parameter beyond what its measurement
gives (a test checks it: tests/test_user_measurements.py).
"""

import dataclasses

import numpy as np

from robstiff_drake.diagrams.compliant_arm import modal_frequencies_hz
from robstiff_drake.diagrams.scenario_models import model_stiffness
from robstiff_drake.identification.stiffness.modes import era_modes, impulse_response, merge_close
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.arm_dynamics import ArmInertia
from robstiff_drake.model.milling import Workpiece

# The modal test: 1 kHz sampling for 1 s after each blow, the response's
# noise 1 % of its peak (ASSUMPTION: an accelerometer and hammer with five
# averaged blows per direction).
MODAL_TEST = {"dt_s": 0.001, "duration_s": 1.0, "noise_rel": 0.01}

# Offsets from identification.seed, so each imperfection has its own draw.
_SEEDS = {"inertia": 101, "tcp": 102, "probe": 103, "modal": 104}


def _rng(sc, what):
    return np.random.default_rng([int(sc.model.identification.seed), _SEEDS[what]])


def user_robot(sc, robot):
    """The robot with its links' and payload's masses and inertias as a
    user's file has them (each off by a uniform draw within
    +-identification.inertia_error), else unchanged."""
    err = float(sc.model.identification.inertia_error)
    if err <= 0:
        return robot
    rng = _rng(sc, "inertia")
    links = []
    for link in robot.links:
        fm, fi = 1.0 + err * rng.uniform(-1, 1, 2)
        links.append(dataclasses.replace(link, mass_kg=float(link.mass_kg) * fm,
                                         inertia_kgm2=np.asarray(link.inertia_kgm2, dtype=float) * fi))
    motors = robot.motor_inertia_kgm2
    if motors is not None:
        motors = np.asarray(motors, dtype=float) * (1.0 + err * rng.uniform(-1, 1, 6))
    return dataclasses.replace(robot, links=tuple(links), motor_inertia_kgm2=motors)


def calibrated_tool(sc, tool_m):
    """The tool point (m, flange frame) a TCP calibration gives."""
    e = float(sc.model.identification.tcp_error_mm) / 1e3
    return np.asarray(tool_m, dtype=float) + (e * _rng(sc, "tcp").standard_normal(3) if e > 0 else 0.0)


def probed_workpiece(sc, workpiece):
    """The workpiece with its tops as a touch probe found them."""
    e = float(sc.model.identification.probe_error_mm) / 1e3
    if e <= 0:
        return workpiece
    dz = e * _rng(sc, "probe").standard_normal()
    return Workpiece(workpiece.x_m, workpiece.y_m, workpiece.top_m + dz)


def modal_test_damping(sc, robot, joints, q_rad, tool_m, model_hz):
    """(damping ratios (6,), (fitted frequencies Hz, ratios)): a hammer
    test on the station's joints (model/joint_dynamics.JointModel, drives
    closed) at pose q, the tool's displacement fitted by ERA, mapped on the
    preview's own modes (``model_hz``: its motors-held frequencies)."""
    A, B = joints.continuous()
    J = kin.jacobian(robot.dh, q_rad, tool_m)[:3]
    blows = B[:, 18:24] @ J.T  # a unit impulse of force at the tool, x, y, z
    C = np.zeros((3, A.shape[0]))
    C[:, 0:6] = J  # the tool's displacement
    seed = int(_rng(sc, "modal").integers(2**31))
    Y = impulse_response(A, blows, C, MODAL_TEST["dt_s"], MODAL_TEST["duration_s"], MODAL_TEST["noise_rel"], seed)
    f, z = merge_close(*era_modes(Y, MODAL_TEST["dt_s"]))
    if len(z) == 0:
        raise ValueError("the modal test found no mode")
    return match_modes(model_hz, f, z), (f, z)


def match_modes(model_hz, found_hz, found_ratios, factor=1.3):
    """The damping ratio of each of the model's modes (frequencies
    ``model_hz``, ascending): the found mode's nearest to it in frequency
    (within ``factor``; each found mode serves one model mode), else the
    median of those found (as a user maps a modal test's modes on a
    model's)."""
    out = np.full(len(model_hz), float(np.median(found_ratios)))
    used = set()
    for i, fm in enumerate(model_hz):
        dist = np.abs(np.log(np.asarray(found_hz) / fm))
        for j in np.argsort(dist):
            if dist[j] <= np.log(factor) and j not in used:
                out[i] = found_ratios[j]
                used.add(j)
                break
    return out


_MODAL_TESTS = {}  # the modal test's damping per station setup and pose (a sweep's runs share it)


def user_measured_damping(sc, robot, station, q_rad):
    """The damping ratios a modal test on ``station`` at q finds
    (``modal_test_damping``) on the preview's own modes, once per process
    for a setup."""
    jm = station.joints
    k_model = np.asarray(model_stiffness(sc, robot), dtype=float)
    ident = sc.model.identification
    key = (jm.M.tobytes(), jm.K.tobytes(), jm.D.tobytes(), jm.G.tobytes(), jm.velocity_gain.tobytes(),
           repr(jm.servo), np.asarray(q_rad).tobytes(), int(ident.seed), float(ident.inertia_error),
           k_model.tobytes())
    if key not in _MODAL_TESTS:
        # the preview's own modes (motors held): the user's inertias on the compensator's stiffness
        model_hz = modal_frequencies_hz(ArmInertia(user_robot(sc, robot)).mass_matrix(q_rad), k_model)
        _MODAL_TESTS[key] = modal_test_damping(sc, robot, jm, q_rad, station.tool_m, model_hz)[0]
    return _MODAL_TESTS[key]
