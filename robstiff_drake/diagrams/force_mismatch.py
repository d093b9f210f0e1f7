"""How far the compensator's force model is from the plant's force along a
run: the plant's cutting force (its own law, from the tool's actual motion:
model/plant_cutting.py) against the compensator's linear,
revolution-averaged model with its identified coefficients, evaluated as
the compensator evaluates it (at the tool point, along the planned path's
direction at clock time, at the programmed feed)."""

import numpy as np

from robstiff_drake.diagrams.scenario_models import cutting_setup, model_cutting_setup
from robstiff_drake.model.realtime import DeflectionPredictor

# Samples where the plant's force is below this (N) are not cutting (the approach, the run-out).
CUTTING_N = 10.0


def force_model_mismatch(result):
    """{"rms_N", "max_N", "rms_rel", "plant_rms_N", "law_rms_N", "law_rms_rel",
    "samples"}: over the samples where the plant cuts (|F| > CUTTING_N), the
    force error |F_model - F_plant| (N) of the compensator's model (its
    identified coefficients) and of the scenario's own linear law (``law_``:
    the law and the plan's clock alone, no coefficient error), RMS and
    largest, and relative to the plant's RMS force."""
    cell = result.cell
    sc = cell.scenario
    t, w = result.logs["cutting_wrench"]
    ts, x = result.logs["state"]
    idx = np.clip(np.searchsorted(ts, t), 0, len(ts) - 1)
    kin = DeflectionPredictor(cell.robot.dh, cell.robot.joint_stiffness_Nm_per_rad, cell.tool_m)
    _, model, workpiece = model_cutting_setup(sc)
    _, law, _ = cutting_setup(sc)
    path = cell.path
    F = w[:, :3]
    cutting = np.linalg.norm(F, axis=1) > CUTTING_N
    err_m, err_l = [], []
    for k in np.flatnonzero(cutting):
        p = kin.pose_only(x[idx[k], :6])[9:]
        u, feed = path.feed_direction(t[k]), path.programmed_speed(t[k])
        err_m.append(np.linalg.norm(model.average_wrench(p, u, workpiece, feed)[:3] - F[k]))
        err_l.append(np.linalg.norm(law.average_wrench(p, u, workpiece, feed)[:3] - F[k]))
    if not err_m:
        return {"samples": 0}
    err_m, err_l = np.array(err_m), np.array(err_l)
    plant_rms = float(np.sqrt(np.mean(np.sum(F[cutting] ** 2, axis=1))))
    rms = float(np.sqrt(np.mean(err_m ** 2)))
    law_rms = float(np.sqrt(np.mean(err_l ** 2)))
    return {"rms_N": rms, "max_N": float(err_m.max()), "rms_rel": rms / plant_rms, "plant_rms_N": plant_rms,
            "law_rms_N": law_rms, "law_max_N": float(err_l.max()), "law_rms_rel": law_rms / plant_rms,
            "samples": int(len(err_m))}
