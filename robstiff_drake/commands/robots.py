"""``robstiff robots``: the robot library (models/*.yaml), one robot a line:
name, manufacturer, model, kinematic convention, joint stiffness range and
where the kinematics come from."""

import numpy as np

from robstiff_drake.io import check_outputs, emit_json
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import library_robots
from robstiff_drake.progress import wrote


def library():
    """Every library robot as a dict (the JSON's rows)."""
    rows = []
    for name in library_robots():
        robot = load_robot(name)
        rows.append({
            "name": robot.name,
            "manufacturer": robot.manufacturer,
            "model": robot.model,
            "convention": robot.convention,
            "controller_map": "identity" if robot.joint_map.is_identity else
            ("coupled joints" if robot.joint_map.coupling else "sign flips / offsets"),
            "source": robot.citation,
            "file": robot.source,
            "mass_kg": robot.total_mass_kg,
            "joint_stiffness_Nm_per_rad": robot.joint_stiffness_Nm_per_rad,
            "joint_limits_deg": np.rad2deg(np.c_[robot.q_lower_rad, robot.q_upper_rad]),
        })
    return rows


def run(*, json_out=None):
    check_outputs(files={"--json": json_out})
    rows = library()
    if json_out is not None:
        emit_json({"robots": rows}, json_out)
    if json_out != "-":
        print(f"{'name':14s} {'manufacturer':12s} {'model':26s} {'convention':12s} {'controller':21s} source")
        for r in rows:
            print(f"{r['name']:14s} {r['manufacturer']:12s} {r['model']:26s} {r['convention']:12s} "
                  f"{r['controller_map']:21s} {r['source']}")
        print("use one with --robot NAME, or give your own robot file with --robot PATH.yaml (docs/your_robot.md)")
    wrote(json_out, to_stderr=json_out == "-")
    return 0
