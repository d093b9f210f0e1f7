"""Stiffness campaigns with a setup mistake (the user's declaration differs
from what the cell did), made by Drake, for the diagnosis's findings.

Nothing here comes from the diagnosis (its candidates, dictionary, terms,
synth) nor from the package's kinematics: the IRB6400 is Drake's
MultibodyPlant (tests/open_world.py's DrakeRobot), each joint a linear
spring at the file's nominal stiffness, the loaded configuration Drake's
static equilibrium (load torques by MultibodyPlant.CalcGeneralizedForces,
fixed-point iteration, so the load's geometric stiffness is in it), the
displacement Drake's forward kinematics of the measured point, loaded minus
unloaded, plus Gaussian CMM noise of 0.01 mm per component.  30 poses x 4
loads of 300 N in random directions.

Kinds (the sizes are the issue's, beyond the typical ranges of
robstiff_drake/identification/diagnosis/plausibility.py):

  none        the six springs only
  tool_point  the load acts (and the instrument reads) 250 mm beyond the
              declared tool point along the flange's z axis (a tool left
              out of the `# tool_mm:` line)
  untared     the force sensor reads the applied force plus a bias of
              (15, -10, 20) N (not tared before the campaign)
  soft_forearm  the forearm bends: the tool point moves by 0.3 um/N times
              the force across the forearm (the axis of joint 4, taken from
              Drake), a soft forearm or a loose joint
  mm_as_m     the displacements written 1000x too large (millimetres read as
              metres somewhere before the file)
"""

from dataclasses import dataclass

import numpy as np
import open_world as ow

from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign
from robstiff_drake.model.robot import load_robot

NOISE_MM = 0.01
FORCE_N = 300.0
N_ROWS, LOADS_PER_POSE = 120, 4
DECLARED_TOOL_M = ow.TOOL_M  # (0, 0, 0.35) m on the flange
TOOL_SHIFT_M = np.array([0.0, 0.0, 0.25])
BIAS_N = np.array([15.0, -10.0, 20.0])
FOREARM_M_PER_N = 0.3e-6
KINDS = ("none", "tool_point", "untared", "soft_forearm", "mm_as_m")
# the term each kind should be traced to (None: nothing; mm_as_m is refused before any fit)
EXPECTED = {"none": None, "tool_point": "tool_offset", "untared": "force_bias", "soft_forearm": "link_compliance",
            "mm_as_m": None}


def _equilibrium(robot, k, q_cmd, force_N, point_m, iterations=12):
    q = robot.full_q(q_cmd)
    for _ in range(iterations):
        tau = robot.load_torques(q, force_N, point_m)[robot.arm]
        q_new = robot.full_q(q_cmd + tau / k)
        done = np.max(np.abs(q_new - q)) < 1e-13
        q = q_new
        if done:
            break
    return q


def _forearm_axis(robot, q):
    """World direction of joint 4's axis (along the forearm) at q, by Drake."""
    plant, ctx = robot.plant, robot.context
    plant.SetPositions(ctx, q)
    joint = plant.GetJointByName("joint_4")
    X = joint.frame_on_child().CalcPoseInWorld(ctx)
    return X.rotation().matrix() @ joint.revolute_axis()


@dataclass
class SetupCampaign:
    kind: str
    campaign: StiffnessCampaign
    declared_tool_m: np.ndarray
    comments: list  # the file's comment lines (tests/open_world.py's to_csv writes them)


def make_campaign(kind, seed, *, n=N_ROWS, noise_mm=NOISE_MM):
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind}")
    rng = np.random.default_rng(seed)
    model = load_robot()
    k = np.asarray(model.joint_stiffness_Nm_per_rad, dtype=float)
    robot = ow.DrakeRobot(model)
    n_poses = int(np.ceil(n / LOADS_PER_POSE))
    pose_idx = np.repeat(np.arange(n_poses), LOADS_PER_POSE)[:n]
    q_cmd = ow.sample_poses(robot, rng, n_poses)[pose_idx]
    dirs = rng.normal(size=(n, 3))
    force = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * FORCE_N
    point = DECLARED_TOOL_M + (TOOL_SHIFT_M if kind == "tool_point" else 0.0)
    d = np.zeros((n, 3))
    for i in range(n):
        q0 = robot.full_q(q_cmd[i])
        q1 = _equilibrium(robot, k, q_cmd[i], force[i], point)
        d[i] = robot.point(q1, point) - robot.point(q0, point)
        if kind == "soft_forearm":
            u = _forearm_axis(robot, q1)
            d[i] += FOREARM_M_PER_N * (force[i] - np.dot(force[i], u) * u)
    reported = force + (BIAS_N if kind == "untared" else 0.0)
    disp_mm = d * 1e3 + rng.normal(scale=noise_mm, size=d.shape)
    if kind == "mm_as_m":
        disp_mm = disp_mm * 1e3
    pose = [f"P{i + 1:03d}" for i in pose_idx]
    comments = [f"Stiffness campaign made by tests/setup_errors.py (Drake MultibodyPlant): {kind}, seed {seed}."]
    camp = StiffnessCampaign(f"setup_errors_{kind}", model.controller_deg(q_cmd), reported, np.zeros((n, 3)), disp_mm,
                             None, pose, np.arange(1, n + 1, dtype=float), np.arange(n) + 4, comments, False,
                             tool_mm=DECLARED_TOOL_M * 1e3)
    return SetupCampaign(kind, camp, DECLARED_TOOL_M.copy(), comments)
