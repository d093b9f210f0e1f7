"""Laser-tracker accuracy campaigns made by Drake (``robstiff synth
tracker``): the arm as a MultibodyPlant with its geometry perturbed, sagging under its own weight
through compliant joints, measured by a tracker standing somewhere in the
cell, which drifts, with its noise.

Nothing here comes from the diagnosis (identification/tracker/) nor
from the package's kinematics: the perturbed arm is a robot file's URDF
(model/description.py, the project's URDF writer) parsed by Drake; Drake
gives the measured point (CalcPointsPositions in the tracker's frame, the
world) and gravity's generalized forces (CalcGravityGeneralizedForces);
the static equilibrium K (q - q_cmd - te) = tau_g(q) is solved here by
fixed-point iteration.

Sizes (drawn per campaign, each within what the calibration literature
reports for large industrial arms):
  joint zero offsets     0.01-0.1 deg, random sign
  link lengths (a, d)    0.1-1 mm on the non-zero ones, 0-0.2 mm on the zero ones
  link twists (alpha)    0.005-0.05 deg; Hayati's tilt between parallel axes the same
  joint stiffness        0.7-1.4x the robot file's (the file's values are assumptions)
  sag                    whatever the masses and that stiffness give (0.5-2 mm for a large arm)
  transmission error     optional: 10-50 urad once per turn of a joint, random phase
  base tilt              optional: the base on two floor joints with springs of 1-3e7 N*m/rad
  measured point         the tracker's target 100-300 mm from the flange, the file's guess 1-5 mm off
  tracker                2.5-4 m from the robot, any heading, level within 0.3 deg
  drift                  optional: the tracker's frame moves 0.05-0.3 mm over the campaign
  noise                  0.02-0.05 mm per component (given)
The true values are returned with the campaign.
"""

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, RevoluteJoint, SpatialInertia, UnitInertia

from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import MultibodyForces

from robstiff_drake.model.description import make_urdf
from robstiff_drake.plant import JOINT_NAMES

PARALLEL_SIN = np.sin(np.deg2rad(10.0))


@dataclass
class TrackerWorld:
    csv_text: str
    true: dict  # the planted values
    robot_true: object  # the perturbed RobotModel the plant was made from
    n: int


def _perturb(robot, rng, tilt_between_parallel=True):
    dh = robot.dh
    n = 6
    dtheta = np.deg2rad(rng.uniform(0.01, 0.1, n) * rng.choice([-1, 1], n))
    def lengths(v):
        out = np.where(np.abs(v) > 1e-9, rng.uniform(0.1e-3, 1e-3, n), rng.uniform(0, 0.2e-3, n))
        return out * rng.choice([-1, 1], n)
    dd, da = lengths(dh.d_m), lengths(dh.a_m)
    dalpha = np.deg2rad(rng.uniform(0.005, 0.05, n) * rng.choice([-1, 1], n))
    beta = np.zeros(n)
    if tilt_between_parallel:
        par = np.abs(np.sin(dh.alpha_rad)) < PARALLEL_SIN
        beta[par] = np.deg2rad(rng.uniform(0.005, 0.05, par.sum()) * rng.choice([-1, 1], par.sum()))
    if robot.convention == "modified_dh":  # the last standard link has no row: keep its a, alpha, beta exact
        da[5], dalpha[5], beta[5] = 0.0, 0.0, 0.0
    new = replace(dh, home_rad=dh.home_rad + dtheta, d_m=dh.d_m + dd, a_m=dh.a_m + da,
                  alpha_rad=dh.alpha_rad + dalpha, beta_rad=beta if np.any(beta) else None)
    return new, {"dtheta_rad": dtheta, "dd_m": dd, "da_m": da, "dalpha_rad": dalpha, "beta_rad": beta}


class FlangeQueries:
    """What Drake says of a point fixed on the flange of ``self.plant`` (at
    ``self.context``, the flange body ``self.flange``): its position and the
    generalized forces of a force applied there.  The tests' independent
    Drake arm (tests/open_world.py) asks the same questions."""

    def point(self, q, p_flange):
        """Position (m, world) of a point fixed on the flange."""
        self.plant.SetPositions(self.context, q)
        return self.plant.CalcPointsPositions(self.context, self.flange.body_frame(),
                                              np.reshape(p_flange, (3, 1)), self.plant.world_frame())[:, 0]

    def load_torques(self, q, force_N, p_flange):
        """Generalized forces of a force (N, world frame) at a flange point (m), by Drake."""
        plant, ctx = self.plant, self.context
        plant.SetPositions(ctx, q)
        forces = MultibodyForces(plant)
        R_WB = plant.EvalBodyPoseInWorld(ctx, self.flange).rotation().matrix()
        self.flange.AddInForce(ctx, R_WB @ np.asarray(p_flange, float), SpatialForce(np.zeros(3), np.asarray(force_N, float)),
                               plant.world_frame(), forces)
        return plant.CalcGeneralizedForces(ctx, forces)


class Arm(FlangeQueries):
    """The perturbed arm in Drake, its base welded (or on two compliant floor
    joints) at the pose X_WB in the tracker's frame (the world)."""

    def __init__(self, robot, X_WB, base_k=None):
        self.robot = robot
        self.plant = plant = MultibodyPlant(time_step=0.0)
        with tempfile.TemporaryDirectory(prefix="tracker_world_") as folder:
            urdf = Path(folder) / f"{robot.name}.urdf"
            urdf.write_text(make_urdf(robot))
            (instance,) = Parser(plant).AddModels(str(urdf))
        base = plant.GetFrameByName(robot.links[0].name, instance)
        self.base_joints = []
        if base_k is not None:
            inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia(0.01, 0.01, 0.01))
            bx = plant.AddRigidBody("tilt_x", instance, inertia)
            by = plant.AddRigidBody("tilt_y", instance, inertia)
            floor = plant.AddFrame(FixedOffsetFrame("floor", plant.world_frame(), X_WB))
            plant.AddJoint(RevoluteJoint("floor_x", floor, bx.body_frame(), [1.0, 0.0, 0.0]))
            plant.AddJoint(RevoluteJoint("floor_y", bx.body_frame(), by.body_frame(), [0.0, 1.0, 0.0]))
            plant.WeldFrames(by.body_frame(), base, RigidTransform())
        else:
            plant.WeldFrames(plant.world_frame(), base, X_WB)
        plant.Finalize()
        self.context = plant.CreateDefaultContext()
        self.arm = [plant.GetJointByName(n).position_start() for n in JOINT_NAMES]
        if base_k is not None:
            self.base_joints = [plant.GetJointByName(n).position_start() for n in ("floor_x", "floor_y")]
        self.base_k = base_k
        self.flange = plant.GetBodyByName("flange")
        self.k = np.asarray(robot.joint_stiffness_Nm_per_rad, dtype=float)

    def equilibrium(self, q_link_cmd, iterations=30, force_N=None, p_flange=None):
        """Positions with the joints (and base) sagged under gravity (and a force at a flange point)."""
        q = np.zeros(self.plant.num_positions())
        q[self.arm] = q_link_cmd
        for _ in range(iterations):
            self.plant.SetPositions(self.context, q)
            tau = self.plant.CalcGravityGeneralizedForces(self.context)
            if force_N is not None:
                tau = tau + self.load_torques(q, force_N, p_flange)
            new = q.copy()
            new[self.arm] = q_link_cmd + tau[self.arm] / self.k
            if self.base_joints:
                new[self.base_joints] = tau[self.base_joints] / self.base_k
            if np.max(np.abs(new - q)) < 1e-14:
                q = new
                break
            q = new
        return q


def _poses(robot, rng, n, frac=0.7):
    """Model angles (rad) of controller angles drawn in the middle ``frac`` of the working ranges."""
    lo, hi = robot.q_lower_rad, robot.q_upper_rad
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * frac
    half = np.minimum(half, np.deg2rad(170.0))
    return robot.joint_map.to_model(rng.uniform(mid - half, mid + half, size=(n, 6)))


def make_tracker_campaign(robot, seed, *, n=600, noise_mm=0.03, transmission=False, base_tilt=False, drift=True,
                          extra_columns=False, pose_seed=None, clock=True, unnamed=0.0, loads=False,
                          periodic=(), coupled=0.0):
    """A tracker campaign of ``robot`` (the robot file the user has) as
    Drake's perturbed plant measures it; see the module docstring.  The arm,
    tracker and target follow from ``seed``; ``pose_seed`` (when given)
    draws other poses, noise and drift: a second campaign of the same arm
    in the same session.  ``clock``: write the t_s column.  ``unnamed``
    (rad): an error no named effect holds, joints 2 and 3 off by
    unnamed * (sin(3 J + phi3) + sin(4 J + phi4)) (reducer errors at the 3rd
    and 4th harmonic of the joint's turn: the named transmission error has
    the 1st and 2nd; what a non-parametric map can learn).  ``loads``: every
    pose is measured twice, unloaded and under a force of 300-700 N in a
    random direction at the target (the fx, fy, fz columns).  ``periodic``:
    [(joint 1-6, period_deg, amplitude_rad)]: that joint's controller angle
    off by amplitude sin(2 pi J / period + phi) (a reducer's or encoder's
    error of any period; phi drawn from the seed).  ``coupled`` (rad): joint
    3 off by coupled sin(3 (J2 + J3) + phi), an error of the elbow's absolute
    angle that no single joint's periodic error holds."""
    rng = np.random.default_rng(seed)
    dh_true, true = _perturb(robot, rng)
    k_true = robot.joint_stiffness_Nm_per_rad * rng.uniform(0.7, 1.4, 6)
    robot_true = replace(robot, dh=dh_true, joint_stiffness_Nm_per_rad=k_true, name=robot.name + "_true")
    yaw, dist = rng.uniform(-np.pi, np.pi), rng.uniform(2.5, 4.0)
    heading = rng.uniform(-np.pi, np.pi)
    X_WB = RigidTransform(RollPitchYaw(*np.deg2rad(rng.uniform(-0.3, 0.3, 2)), yaw),
                          [dist * np.cos(heading), dist * np.sin(heading), rng.uniform(-1.0, 0.5)])
    base_k = rng.uniform(1e7, 3e7) if base_tilt else None
    arm = Arm(robot_true, X_WB, base_k)
    target = np.array([rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(100, 300)]) * 1e-3
    te_amp = rng.uniform(10e-6, 50e-6, 6) if transmission else np.zeros(6)
    te_phase = rng.uniform(0, 2 * np.pi, 6)
    v_drift = rng.normal(size=3)  # the tracker's frame moves 0.05-0.3 mm over the campaign, linearly in time
    v_drift *= rng.uniform(0.05e-3, 0.3e-3) / np.linalg.norm(v_drift) if drift else 0.0
    extra_phase = np.random.default_rng([seed, 99]).uniform(0, 2 * np.pi, len(periodic) + 1)  # apart from rng
    G = robot.joint_map.G
    guess = target * 1e3 + rng.normal(size=3) / np.sqrt(3) * rng.uniform(1, 5)
    if pose_seed is not None:
        rng = np.random.default_rng([seed, pose_seed])
    rows, q_ctrl_all, pts, times, forces = 0, [], [], [], []
    t = 0.0
    while rows < n:
        q_model = _poses(robot, rng, 1)[0]
        q_ctrl = robot.joint_map.to_controller(q_model)
        if not robot.within_limits(q_model):
            continue
        p_nom = arm.point(arm.equilibrium(q_model, iterations=1), target)
        base = X_WB.translation()
        if p_nom[2] - base[2] < 0.2 or np.hypot(*(p_nom - base)[:2]) < 0.5:
            continue
        te_ctrl = te_amp * np.sin(q_ctrl + te_phase)  # the reducers' error, on the controller's joints
        if unnamed:
            te_ctrl[1:3] += unnamed * (np.sin(3 * q_ctrl[1:3] + te_phase[:2]) + np.sin(4 * q_ctrl[1:3] + te_phase[2:4]))
        for (j, period_deg, amp), ph in zip(periodic, extra_phase):
            te_ctrl[j - 1] += amp * np.sin(2 * np.pi * np.rad2deg(q_ctrl[j - 1]) / period_deg + ph)
        if coupled:
            te_ctrl[2] += coupled * np.sin(3 * (q_ctrl[1] + q_ctrl[2]) + extra_phase[-1])
        q_link = q_model + G @ te_ctrl
        for force in ([np.zeros(3), None] if loads else [None]):
            if force is None and loads:
                f = rng.normal(size=3)
                force = f / np.linalg.norm(f) * rng.uniform(300.0, 700.0)
            # the file gives the force in the robot's base frame; Drake's world is the tracker's frame
            q = arm.equilibrium(q_link, force_N=None if force is None else X_WB.rotation().matrix() @ force,
                                p_flange=target)
            t += rng.uniform(3.0, 8.0)  # s between measurements (an automated campaign)
            p = arm.point(q, target) + rng.normal(scale=noise_mm * 1e-3, size=3)
            q_ctrl_all.append(np.rad2deg(q_ctrl))
            pts.append(p * 1e3)
            times.append(t)
            forces.append(np.zeros(3) if force is None else force)
            rows += 1
    n = rows
    q_ctrl_all, times, forces = np.array(q_ctrl_all), np.array(times), np.array(forces)
    pts = np.array(pts) + np.outer(times / times[-1], v_drift) * 1e3
    true.update(k_Nm_per_rad=k_true, tool_mm=target * 1e3, tool_guess_mm=guess, X_WB=X_WB.GetAsMatrix4(),
                transmission_rad=te_amp, periodic=list(periodic),
                periodic_phase_rad=extra_phase[:len(periodic)], drift_mm=v_drift * 1e3, base_k=base_k,
                noise_mm=noise_mm,
                effects=["joint_offsets", "link_lengths", "link_twists", "joint_compliance"]
                + [f"periodic_j{j + 1}" for j in range(6) if te_amp[j] > 0]
                + [f"periodic_j{j}" for j in sorted({j for j, _, _ in periodic} | ({2, 3} if unnamed else set()))]
                + (["base_tilt"] if base_tilt else []) + (["time_drift"] if drift else []))
    head = ["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z"] + (["t_s"] if clock else []) + \
        (["fx", "fy", "fz"] if loads else [])
    lines = [f"# Tracker campaign made by robstiff synth tracker (Drake plant of a perturbed {robot.name}); seed {seed}",
             "# tool_mm: " + ", ".join(f"{v:.3f}" for v in guess)]
    if extra_columns:  # what a tracker's export adds: units in the header, a point id, an uncertainty, a timestamp
        lines.append("Point ID;J1 [deg];J2 [deg];J3 [deg];J4 [deg];J5 [deg];J6 [deg];X [mm];Y [mm];Z [mm];"
                     "U95 [mm];Time [s];Timestamp")
        for i in range(n):
            cells = [f"P{i + 1}"] + [f"{v:.6f}".replace(".", ",") for v in q_ctrl_all[i]] + \
                    [f"{v:.5f}".replace(".", ",") for v in pts[i]] + ["0,015", f"{times[i]:.1f}".replace(".", ","),
                                                                      f"2026-11-25T10:{i % 60:02d}:00"]
            lines.append(";".join(cells))
    else:
        lines.append(",".join(head))
        for i in range(n):
            lines.append(",".join([f"{v:.6f}" for v in q_ctrl_all[i]] + [f"{v:.5f}" for v in pts[i]]
                                  + ([f"{times[i]:.1f}"] if clock else [])
                                  + ([f"{v:.3f}" for v in forces[i]] if loads else [])))
    return TrackerWorld("\n".join(lines) + "\n", true, robot_true, n)
