"""Is a compensation loop stable before it streams to a robot?  The linear
loop model (model/loop_model.py) of the arm at one pose, its drives, the
wrist sensor (which also feels the payload's inertia), the force filter,
the controller period and delays, and the compensator's deflection model,
in plain numpy: the mass matrix and the weight's stiffness from
model/arm_dynamics.py (the rigid-body quantities Drake's plant gives,
tests/test_robot_file_schema.py), no Drake.

Two modes: in air (no process stiffness) and cutting (a nominal process
stiffness, ``NOMINAL_PROCESS_STIFFNESS_N_PER_M``, turned to the feed).
The damping ratios are those of the arm's modes with the drives closed
(model/joint_dynamics.linear_joints), the drives' integral corner chosen
from the arm's first antiresonance when the servo's rule says so: the
caller tunes the drives once (at the start pose: ``LoopSetup.arm(...)[0]
.servo`` is then the tuned servo) and checks the poses along the path with
it (cell/loop_guard.LoopGuard.along).

The margin.  The verdict is taken with the arm's damping at
``MARGIN_DAMPING_RATIO`` (2 %) on every mode, not at the 5 % the plant
assumes (joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO): the damping is the
model's least certain number (experimental modal analyses of industrial
arms report 2-10 %), and the loop's instability is the loss of the first
mode's damping (the sensor feeds the payload's inertial force back through
the filter; docs/results.md).  A loop stable at 2 % keeps a margin of
3 % of critical damping on its least damped mode at the assumed 5 %; a
loop stable only at 5 % would diverge on an arm at the low end of the
published range.  A fixed bound on the spectral radius per period (say
0.98) cannot be the margin: the arm's own first mode at 5 % damping sits
at 0.9957 per 4 ms period with no compensation at all (every loop would be
refused), and a bound per period means another damping at another period.

Units: angles in rad (the model's joints), stiffness N*m/rad, process
stiffness N/m, frequencies Hz, times s.
"""

from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.model import joint_dynamics
from robstiff_drake.model.arm_dynamics import ArmInertia
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.loop_model import LoopModel

# ASSUMPTION (see the module docstring): the verdict's damping, the low end of the 2-10 % that experimental
# modal analyses of industrial arms report (joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO gives the source).
MARGIN_DAMPING_RATIO = 0.02
# A loop is called stable when its spectral radius per controller period at MARGIN_DAMPING_RATIO is at most this.
STABLE_RADIUS = 1.0
# ASSUMPTION: the transport's own delay between the controller's message and the tick the answer acts at,
# in controller periods, on top of compensate's --delay-steps: one (the answer is read at the controller's
# next cycle; the scenarios' controller.delay_steps, `sim-cell --transport-delay-cycles`).
TRANSPORT_DELAY_STEPS = 1
# ASSUMPTION: the process stiffness K_p = dF/dp (N/m; rows force x, y, z, columns tool displacement x, y, z)
# of the paper's Table 3 pass (diagrams/block_milling.yaml: 75 mm face mill, 3 mm deep, 6063, 20 mm/s,
# 3600 rpm, 3.0 kW at the spindle) at mid-pass, in the feed's frame (x along the feed, z up, spindle down):
# model/loop_model.process_stiffness of the scenario's force model, rounded to 0.1 N/mm
# (tests/test_loop_check.py recomputes it).  A heavier cut is stiffer: the check is for a cut of this size.
NOMINAL_PROCESS_STIFFNESS_N_PER_M = 1e3 * np.array([[0.0, -0.2, 45.1],
                                                   [0.0, 3.9, -39.2],
                                                   [0.0, 0.5, -7.7]])
# The tool point must move this far along a path (m) for a pose on it to have a feed direction.
FEED_DISTANCE_M = 1e-3
CUTOFF_RESOLUTION_HZ = 0.1  # the largest stable cutoff is given to this, rounded down
MIN_CUTOFF_HZ = 0.1  # the search's lower end
SEARCH_UPPER_HZ = 20.0  # its upper end where the compensator's filter is not a low-pass


def gravity_stiffness(robot, q_rad, delta_rad=1e-6):
    """d tau_gravity / dq (6, 6, N*m/rad) at model angles q, by central
    differences of arm_dynamics.ArmInertia.gravity_torques."""
    q = np.asarray(q_rad, dtype=float)
    arm = ArmInertia(robot)
    G = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = delta_rad
        G[:, k] = (arm.gravity_torques(q + e) - arm.gravity_torques(q - e)) / (2 * delta_rad)
    return G


def payload_inertial_wrench_map(robot, q, tool_m=None):
    """L (6, 6): the wrench the payload's inertia puts on the sensor, at the
    tool point (``tool_m``, flange frame, m; None: the robot file's) in the
    base frame, per joint acceleration at q (rad/s^2): force -m a_com,
    moment -(r_com - r_tool) x m a_com - I alpha."""
    pl = robot.payload
    tool = pl.tool_point_m if tool_m is None else np.asarray(tool_m, dtype=float)
    J_com = kin.jacobian(robot.dh, q, pl.com_m)
    R = kin.frames(robot.dh, q)[6, :3, :3]
    r = R @ (pl.com_m - tool)  # tool point -> centre of mass, base frame
    skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    force = -pl.mass_kg * J_com[:3]
    return np.vstack([force, skew @ force - R @ pl.inertia_about_com_kg_m2 @ R.T @ J_com[3:]])


def process_stiffness_along(feed_xy):
    """The nominal process stiffness (3, 3, N/m) for a feed along the base
    frame's horizontal direction ``feed_xy`` (None or zero: along +x)."""
    f = np.zeros(2) if feed_xy is None else np.asarray(feed_xy, dtype=float)[:2]
    a = float(np.arctan2(f[1], f[0])) if np.linalg.norm(f) > 0 else 0.0
    c, s = np.cos(a), np.sin(a)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return R @ NOMINAL_PROCESS_STIFFNESS_N_PER_M @ R.T


@dataclass
class LoopSetup:
    """What the check needs of the compensator and the robot."""

    robot: object  # model.robot.RobotModel (links, payload, tool point)
    q_rad: np.ndarray  # (6,) model angles of the pose
    k_Nm_per_rad: np.ndarray  # (6,) the compensator's joint stiffness (also the arm's best estimate)
    servo: object  # model.servo.ServoParameters of the controller
    sensor_rate_hz: float
    period_s: float
    delay_steps: int  # the compensator's own; transport_delay_steps is added
    filter_order: int = 2
    tool_m: np.ndarray = None  # (3,) the tool point, flange frame (m); None: the robot file's, else the flange
    k_plant_Nm_per_rad: np.ndarray = None  # (6,) the arm's own joint stiffness when it is known apart (a scenario)
    transport_delay_steps: int = TRANSPORT_DELAY_STEPS  # a scenario's delay_steps already counts the transport's
    _arm: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if self.tool_m is None:
            t = self.robot.payload.tool_point_m
            self.tool_m = np.zeros(3) if t is None else np.asarray(t, dtype=float)

    def arm(self, damping_ratio):
        """(JointModel, J, L) at the pose for one damping ratio (cached)."""
        key = tuple(np.broadcast_to(np.asarray(damping_ratio, dtype=float), 6).tolist())
        if key not in self._arm:
            if "M" not in self._arm:
                tool = self.tool_m  # (the robot file's payload: its mass, centre of mass and inertia)
                self._arm["M"] = ArmInertia(self.robot).mass_matrix(self.q_rad)
                self._arm["G"] = gravity_stiffness(self.robot, self.q_rad)
                self._arm["J"] = kin.jacobian(self.robot.dh, self.q_rad, tool)
                self._arm["L"] = payload_inertial_wrench_map(self.robot, self.q_rad, tool)
            M, G = self._arm["M"], self._arm["G"]
            # the arm's gears: the compensator's stiffness (an identified model: the best estimate there is)
            k = self.k_Nm_per_rad if self.k_plant_Nm_per_rad is None else self.k_plant_Nm_per_rad
            self._arm[key] = joint_dynamics.linear_joints(M, G, np.diag(np.asarray(k, dtype=float)), np.array(key),
                                                          self.servo, joint_dynamics.motor_inertia(self.robot, M))
        return self._arm[key], self._arm["J"], self._arm["L"]

    def loop(self, filter_ba, damping_ratio, gain=1.0):
        """The LoopModel (``gain`` 0: the arm and its drives without the correction)."""
        jm, J, L = self.arm(damping_ratio)
        return LoopModel(M=jm.M, K=jm.K, beta_s=None, J=J,
                         C_model=float(gain) / np.asarray(self.k_Nm_per_rad, dtype=float),
                         filter_ba=filter_ba, rate_hz=self.sensor_rate_hz, period_s=self.period_s,
                         delay_steps=int(self.delay_steps) + int(self.transport_delay_steps), sensor_inertia=L,
                         gravity_stiffness=jm.G, joints=jm)

    def radius(self, filter_ba, Kp, damping_ratio=MARGIN_DAMPING_RATIO, gain=1.0):
        """The spectral radius of the loop's period map (the arm's modes at
        ``damping_ratio``: one for all, or one per mode; ``gain`` 0: without
        the correction)."""
        return self.loop(filter_ba, damping_ratio, gain).poles(Kp)[1]

    def largest_stable_cutoff_hz(self, upper_hz, modes, upper_unstable=False):
        """The largest low-pass cutoff (Hz, to CUTOFF_RESOLUTION_HZ, rounded
        down) up to ``upper_hz`` at which every process stiffness of
        ``modes`` ({name: Kp}) is stable at MARGIN_DAMPING_RATIO; None when
        not even MIN_CUTOFF_HZ is (``upper_unstable``: ``upper_hz`` is known
        unstable, not checked again).  Bisection: the radius grows with the
        cutoff once the filter lets the arm's first mode through."""

        def stable(f):
            ba = lowpass_coefficients(f, self.sensor_rate_hz, self.filter_order)
            return all(self.radius(ba, Kp) <= STABLE_RADIUS for Kp in modes.values())

        lo, hi = MIN_CUTOFF_HZ, float(upper_hz)
        if not stable(lo):
            return None
        if not upper_unstable and stable(hi):
            return hi
        while hi - lo > CUTOFF_RESOLUTION_HZ / 2:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        return round(float(np.floor(lo / CUTOFF_RESOLUTION_HZ + 1e-9) * CUTOFF_RESOLUTION_HZ), 6)


@dataclass
class Verdict:
    """The check's result: per mode ("air", "cutting") the spectral radius
    at the margin's damping and at the assumed one; ``unstable``: the modes
    whose radius at the margin's damping exceeds STABLE_RADIUS."""

    radius: dict  # mode -> radius at MARGIN_DAMPING_RATIO
    radius_assumed: dict  # mode -> radius at joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO
    unstable: list
    largest_stable_cutoff_hz: float | None = None

    def as_dict(self):
        return {"margin_damping_ratio": MARGIN_DAMPING_RATIO,
                "assumed_damping_ratio": joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO,
                "stable_radius": STABLE_RADIUS, "spectral_radius": self.radius,
                "spectral_radius_assumed_damping": self.radius_assumed, "unstable_modes": self.unstable,
                "largest_stable_cutoff_hz": self.largest_stable_cutoff_hz}



def check(setup, filter_ba, modes, *, cutoff_hz=None, search_cutoff=True, assumed_damping=True):
    """The verdict for the compensator's filter (b, a) and the process
    stiffnesses ``modes`` ({name: Kp (3, 3) N/m}); with an unstable mode,
    the largest stable low-pass cutoff up to ``cutoff_hz`` (the filter's
    own, a low-pass of ``setup.filter_order``), or up to SEARCH_UPPER_HZ
    (``cutoff_hz`` None: another filter; ``search_cutoff`` false: no
    search, None; ``assumed_damping`` false: no radii at the assumed
    damping, an empty dict)."""
    radius = {m: setup.radius(filter_ba, Kp) for m, Kp in modes.items()}
    assumed = {m: setup.radius(filter_ba, Kp, joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO)
               for m, Kp in modes.items()} if assumed_damping else {}
    unstable = [m for m, r in radius.items() if not r <= STABLE_RADIUS]
    v = Verdict(radius, assumed, unstable)
    if unstable and search_cutoff:
        upper = min(cutoff_hz or SEARCH_UPPER_HZ, 0.45 * setup.sensor_rate_hz)
        v.largest_stable_cutoff_hz = setup.largest_stable_cutoff_hz(upper, modes, upper_unstable=upper == cutoff_hz)
    return v
