"""The plant step a scenario runs at: the one it gives, or, when it gives
none, the one the station takes for its arm (``scenario_step_s``: the
largest step up to diagrams/plant_step.DEFAULT_MAX_STEP_S that keeps every
mode stable and resolves the gears' play and a tooth-resolved force, at
the poses the scenario's path visits), with the one line of why."""

import sys

import numpy as np

from robstiff_drake.diagrams import compliant_arm, scenario
from robstiff_drake.diagrams.path_references import planned_path
from robstiff_drake.diagrams.plant_step import chosen_step, step_choice  # noqa: F401 (re-exported)
from robstiff_drake.diagrams.scenario import scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios, plant_stiffness, servo_parameters
from robstiff_drake.model import joint_dynamics


def plant_step_s(sc, robot=None):
    """The plant's discrete step (s): plant_config.time_step, or, when the
    scenario gives none, the step the station takes for its arm (``robot``,
    else the scenario's: ``scenario_step_s``, which writes
    it into the scenario)."""
    return scenario_step_s(sc, robot)


_SAID = set()


def scenario_step_s(sc, robot=None, q_modes_rad=None):
    """The plant step (s) of scenario ``sc``: its plant_config.time_step
    when given; when not (NOT_GIVEN), ``chosen_step`` for its arm
    (``robot``, else the scenario's) at ``q_modes_rad`` (else the poses its
    path visits, diagrams/path_references.planned_path), written into
    sc.plant_config.time_step with the reason in sc._plant_step_choice
    (step, why, robot source) and said once on stderr."""
    h = float(sc.plant_config.time_step)
    if h > 0:
        return h
    robot = robot if robot is not None else scenario_robot(sc)
    if q_modes_rad is None:
        q_modes_rad = compliant_arm.path_poses(planned_path(sc, robot, robot.tool_point(where="the plant step"))[2])
    K = joint_dynamics.stiffness_matrix(np.asarray(plant_stiffness(sc, robot), dtype=float),
                                        sc.plant.coupling_c23_rad_per_Nm)
    jm = compliant_arm.arm_joints(compliant_arm.controller_model(robot), robot, q_modes_rad, K,
                                  plant_damping_ratios(sc), servo_parameters(sc), sc.plant.damping_on)
    tooth = sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth if sc.cutting.mode == "tooth" else None
    h, why = chosen_step(jm, sc.plant.lost_motion_rad, tooth)
    n = scenario.planned_path(sc).duration_s / h  # (the size checks took the largest step: checked again at it)
    if n > scenario.MAX_PLANT_STEPS:
        scenario._fail(sc, "plant_config.time_step", f"{why}: the pass takes {n:.3g} plant steps at it, more "
                                                     f"than the {scenario.MAX_PLANT_STEPS:.0e} a run may take; "
                                                     "shorten the path or raise the feed")
    sc.plant_config.time_step = h
    sc._plant_step_choice = (h, why, robot.source)
    if why not in _SAID:
        _SAID.add(why)
        print(f"robstiff: {why}", file=sys.stderr)
    return h
