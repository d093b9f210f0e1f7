"""The plant's cutting physics (model/plant_cutting.py) and its force
source (systems/milling_force.py): the plant's law reduces to the
compensator's linear one when its extra physics is off, each extra has the
size it states, and the force follows the tool's actual motion, not the
planned path's clock."""

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator

from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics
from robstiff_drake.systems.milling_force import MillingForceSource

from arm_motion import arm_at_pose, moved

CUTTER = Cutter(0.075, 6, 3600.0)
COEFFS = CuttingCoefficients(631, 99, 273, 13, 10, 2.8)
LINEAR = MillingForceModel(CUTTER, COEFFS, 0.02)
WP = Workpiece.from_boxes([[-0.05, 0.1, -0.02, 0.03, 0.003], [0.02, 0.05, -0.05, 0.0, 0.005]])


@pytest.mark.parametrize("u", [(1.0, 0.0), (0.6, 0.8), (-0.8, 0.6)])
def test_with_its_extras_off_the_plant_law_is_the_linear_model(u):
    plant = PlantCuttingLaw(LINEAR, PlantCuttingPhysics.linear())
    for p in ([0.0, 0.0, 0.0], [0.03, -0.01, 0.001], [-0.04, 0.02, 0.0]):
        for feed in (0.01, 0.02, 0.05):
            np.testing.assert_allclose(plant.average_wrench(p, u, WP, feed), LINEAR.average_wrench(p, u, WP, feed),
                                       rtol=1e-9, atol=1e-9)
        t = np.linspace(0.0, 0.02, 9)
        np.testing.assert_allclose(plant.tooth_wrenches(t, p, u, WP, 0.3, 0.03),
                                   LINEAR.tooth_wrenches(t, p, u, WP, 0.3, 0.03), rtol=1e-9, atol=1e-9)


def cutting_only(physics):
    """A law without edge forces (the chip's part alone)."""
    no_edge = MillingForceModel(CUTTER, CuttingCoefficients(631, 99, 273, 0.0, 0.0, 0.0), 0.02)
    return PlantCuttingLaw(no_edge, physics)


def test_the_chip_law_is_kienzle_with_its_exponent_through_the_linear_law_at_the_mean_chip():
    law = cutting_only(PlantCuttingPhysics(runout_m=0.0, flank_wear_m=0.0, flank_wear_per_m=0.0))
    p = [0.0, 0.0, 0.0]
    f1, f2 = (law.average_wrench(p, (1, 0), WP, v) for v in (0.01, 0.04))
    np.testing.assert_allclose(f2[:3], f1[:3] * 4.0 ** 0.75, rtol=1e-9)  # F ~ h^0.75, not h
    h = law.h_ref_m
    Ft, Fr, Fa = law.chip_forces(np.array([h, 2 * h]), np.array([1e-3, 1e-3]))
    np.testing.assert_allclose(Ft[0], 631e6 * 1e-3 * h)  # the linear law's at the reference chip
    np.testing.assert_allclose(Ft[1] / Ft[0], 2.0 ** 0.75)


def test_the_worn_edge_ploughs_more_as_the_cut_goes_on():
    law = PlantCuttingLaw(LINEAR, PlantCuttingPhysics(flank_wear_m=0.02e-3, flank_wear_per_m=0.3e-6))
    Ke0, Ke1 = law.edge_coefficients(0.0), law.edge_coefficients(1000.0)  # after a kilometre of cut
    np.testing.assert_allclose(Ke1[1] - Ke0[1], 300e6 * 0.3e-3)  # sigma_n * dVB on the radial edge force
    np.testing.assert_allclose(Ke1[0] - Ke0[0], 0.3 * 300e6 * 0.3e-3)
    p = [0.0, 0.0, 0.0]
    assert np.linalg.norm(law.average_wrench(p, (1, 0), WP, 0.02, cut_length_m=1000.0)[:3]) > \
        1.2 * np.linalg.norm(law.average_wrench(p, (1, 0), WP, 0.02)[:3])


def test_runout_makes_the_teeth_differ_and_repeat_once_a_revolution():
    law = PlantCuttingLaw(LINEAR, PlantCuttingPhysics(runout_m=10e-6))
    assert np.ptp(law.runout_chip_m) > 15e-6 and abs(law.runout_chip_m.sum()) < 1e-15
    rev, tooth = 60.0 / CUTTER.spindle_rpm, 60.0 / CUTTER.spindle_rpm / CUTTER.n_teeth
    p = [0.0013, 0.0021, 0.0]  # no tooth tip on a box edge at the sampled instants
    t = np.linspace(0.0, tooth, 7)
    w0, w1, w_rev = (law.tooth_wrenches(t + d, p, (1, 0), WP, 0.0, 0.02) for d in (0.0, tooth, rev))
    np.testing.assert_allclose(w_rev, w0, atol=1e-6)  # one revolution later: the same teeth
    assert np.max(np.abs(w1 - w0)[:, :3]) > 5.0  # the next tooth pass: another tooth, another chip
    ideal = PlantCuttingLaw(LINEAR, PlantCuttingPhysics(runout_m=0.0)).tooth_wrenches(t, p, (1, 0), WP, 0.0, 0.02)
    np.testing.assert_allclose(ideal, PlantCuttingLaw(LINEAR, PlantCuttingPhysics(runout_m=0.0)).tooth_wrenches(
        t + tooth, p, (1, 0), WP, 0.0, 0.02), atol=1e-6)  # without runout every tooth pass is alike


@pytest.fixture(scope="module")
def arm(robot):
    return arm_at_pose(robot)


def drive(src, kin, q0, times, points, feed0=0.0):
    """Run the source's updates with the tool put at ``points`` (m from q0's
    tool point) at ``times``, its low-passed feed starting at ``feed0``
    (m/s); the held wrench after the last."""
    sim = Simulator(src)
    ctx = sim.get_mutable_context()
    ctx.SetTime(times[0] - 1e-9)  # (the updates start with the sequence)
    held = ctx.get_discrete_state(int(src._process)).CopyToVector()  # (the direction, feed, travel, history)
    src.set_progress(ctx, np.r_[held[:2], feed0, 0.0], held[4:])
    for t, dx in zip(times, points):
        src.get_input_port().FixValue(ctx, moved(kin, q0, np.asarray(dx)))
        sim.AdvanceTo(t + 1e-6)
    return ctx.get_discrete_state(int(src._w)).CopyToVector()


def test_the_force_follows_the_tool_not_the_plans_clock(arm):
    """The plan turns a corner (+x, then +y) while the tool, held back,
    is still 20 mm before it, moving along +x at 20 mm/s: the plant's
    chip is along +x at the tool's speed, where the plan's clock would
    have it along +y; a tool held at rest makes no chip at all."""
    kin, tool, q0 = arm
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    path = PlannedPath([p0 - [0.1, 0, 0], p0 + [0.02, 0, 0], p0 + [0.02, 0.1, 0]], 0.02)
    wp = Workpiece.from_boxes([[p0[0] - 0.2, p0[0] + 0.2, p0[1] - 0.2, p0[1] + 0.2, p0[2] + 0.003]])
    law = PlantCuttingLaw(LINEAR, PlantCuttingPhysics.linear())
    T = 0.004
    src = MillingForceSource(force_model=law, workpiece=wp, path=path, kinematics=kin, tool_point_m=tool,
                             period_s=T, spindle_body_index=BodyIndex(7))
    # the clock is at 6.5 s (past the corner, 0.12 m along the path: moving +y); the tool is 20 mm before it
    times = 6.5 + T * np.arange(12)
    xs = [[-0.02 + 0.02 * (t - times[-1]), 0.0, 0.0] for t in times]
    assert path.feed_direction(times[-1]) == pytest.approx((0.0, 1.0))
    w = drive(src, kin, q0, times, xs, feed0=0.02)
    _, p = kin.flange_rotation_and_tool_point(moved(kin, q0, np.asarray(xs[-1])))
    tool_way = law.average_wrench(p, (1.0, 0.0), wp, 0.02)
    clock_way = law.average_wrench(p, path.feed_direction(times[-1]), wp, path.programmed_speed(times[-1]))
    np.testing.assert_allclose(w, tool_way, rtol=0.02, atol=0.5)
    assert np.linalg.norm(w[:3] - clock_way[:3]) > 0.5 * np.linalg.norm(clock_way[:3])
    # held at rest (the plan's clock still says 20 mm/s): no chip, no edge ramp either
    src2 = MillingForceSource(force_model=PlantCuttingLaw(LINEAR), workpiece=wp, path=path, kinematics=kin,
                              tool_point_m=tool, period_s=T, spindle_body_index=BodyIndex(7))
    rest = drive(src2, kin, q0, times, [xs[-1]] * len(times))
    assert np.linalg.norm(rest[:3]) < 1e-6
    assert path.speed(times[-1]) > 0.019


def test_a_speed_ramp_thins_the_chip(arm):
    """The tool at half the programmed speed: the plant's chip is half the
    programmed one, its low-passed feed settling there from the programmed
    speed within 0.6 s (FEED_CUTOFF_HZ)."""
    kin, tool, q0 = arm
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    path = PlannedPath([p0 - [0.1, 0, 0], p0 + [0.1, 0, 0]], 0.02)
    wp = Workpiece.from_boxes([[p0[0] - 0.2, p0[0] + 0.2, p0[1] - 0.2, p0[1] + 0.2, p0[2] + 0.003]])
    law = PlantCuttingLaw(LINEAR, PlantCuttingPhysics.linear())
    T = 0.004
    src = MillingForceSource(force_model=law, workpiece=wp, path=path, kinematics=kin, tool_point_m=tool,
                             period_s=T, spindle_body_index=BodyIndex(7))
    times = 3.0 + T * np.arange(150)
    w = drive(src, kin, q0, times, [[0.01 * (t - times[-1]), 0.0, 0.0] for t in times], feed0=0.02)
    _, p = kin.flange_rotation_and_tool_point(moved(kin, q0, np.zeros(3)))
    np.testing.assert_allclose(w, law.average_wrench(p, (1.0, 0.0), wp, 0.01), rtol=0.02, atol=0.5)
    assert np.linalg.norm(w[:3] - law.average_wrench(p, (1.0, 0.0), wp, 0.02)[:3]) > 10.0


def at_an_angle(kin, q0, src, law, angle_deg, n=150, T=0.004):
    """The path runs along +x; the tool moves at ``angle_deg`` to it at
    20 mm/s for n updates (the held direction starting along the path, the
    feed at 20 mm/s): (the source's held wrench, the law's wrench with the
    chip along the tool's motion at its speed, the same along the path at
    the tool's progress along it)."""
    a = np.deg2rad(angle_deg)
    way = np.array([np.cos(a), np.sin(a), 0.0])
    times = 5.0 + T * np.arange(n)
    w = drive(src, kin, q0, times, [0.02 * (t - times[-1]) * way for t in times], feed0=0.02)
    _, p = kin.flange_rotation_and_tool_point(moved(kin, q0, np.zeros(3)))
    return (w, law.average_wrench(p, way[:2], src._workpiece, 0.02),
            law.average_wrench(p, (1.0, 0.0), src._workpiece, 0.02 * np.cos(a)))


def straight_path_source(kin, tool, q0, law, cls=MillingForceSource):
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    path = PlannedPath([p0 - [0.1, 0, 0], p0 + [0.1, 0, 0]], 0.02)
    wp = Workpiece.from_boxes([[p0[0] - 0.2, p0[0] + 0.2, p0[1] - 0.2, p0[1] + 0.2, p0[2] + 0.003]])
    return cls(force_model=law, workpiece=wp, path=path, kinematics=kin, tool_point_m=tool, period_s=0.004,
               spindle_body_index=BodyIndex(7))


@pytest.mark.xfail(strict=True, reason="issue 29: the default plant's chip direction is the program's where the "
                   "tool is (cutting.chip: program); the chip that follows the tool is the option cutting.chip: "
                   "regenerative (tests/test_regenerative_chip.py passes this situation with it), whose chatter "
                   "on the paper's block studies/regenerative_chatter.py measures (docs/results.md)")
def test_the_chip_turns_with_the_tools_motion_not_the_programs(arm):
    """The program runs along +x; the tool moves at 30 degrees to it (a
    tool pushed off its path): a chip that follows the tool is along its
    motion, and its force the law's along that direction, not along the
    program's.  Fails while the plant takes the program's direction."""
    kin, tool, q0 = arm
    law = PlantCuttingLaw(LINEAR)
    w, tool_way, path_way = at_an_angle(kin, q0, straight_path_source(kin, tool, q0, law), law, 30.0)
    assert np.linalg.norm(tool_way[:3] - path_way[:3]) > 0.2 * np.linalg.norm(path_way[:3])
    np.testing.assert_allclose(w[:3], tool_way[:3], rtol=0.03, atol=1.0)
