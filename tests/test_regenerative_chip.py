"""The regenerative chip (model/regenerative_chip.py) and the plant option
that uses it (cutting.chip: regenerative; systems/regenerative_force.py):
in straight steady cutting it is the plant's tooth-resolved law; a tool
pushed off its path cuts along its own motion; a tool that retreats cuts
nothing; an option without its resolved step is refused."""

import copy

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator

from robstiff_drake.diagrams.milling_cell import check_plant_step
from robstiff_drake.diagrams.scenario import InputError, check_scenario, load_scenario
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.plant_cutting import PlantCuttingLaw
from robstiff_drake.model.regenerative_chip import RegenerativeChip
from robstiff_drake.paths import DIAGRAMS_DIR
from robstiff_drake.systems.regenerative_force import RegenerativeForceSource

from arm_motion import arm_at_pose, moved

CUTTER = Cutter(0.075, 6, 3600.0)
LINEAR = MillingForceModel(CUTTER, CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
WP = Workpiece.from_boxes([[-0.05, 0.1, -0.02, 0.03, 0.003], [0.02, 0.05, -0.05, 0.0, 0.005]])
STEP_S = 0.25e-3


def straight_past(chip, t, p, feed_m_per_s, u, since_s=np.inf, before_m_per_s=0.0):
    """(T, M, 2): the tool centre k tooth periods before each time of t,
    for a tool moving along u at the feed (m/s) through p now, over the
    last ``since_s``, before that at ``before_m_per_s``."""
    back_s = chip._k * chip.tooth_period_s
    back = np.minimum(back_s, since_s) * feed_m_per_s + np.maximum(back_s - since_s, 0.0) * before_m_per_s
    return np.broadcast_to(p[:2] - back[:, None] * np.asarray(u), (len(t), len(back), 2))


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 135.0])
def test_in_straight_steady_cutting_it_is_the_plant_tooth_law(angle_deg):
    """The tool moving along u at 20 mm/s: every tooth's regenerative chip is
    the law's chip along u (runout, Kienzle, edge ramp and wear as they
    are), the wrench the law's tooth-resolved one instant by instant (to
    round-off; the teeth's angles from base x are the law's from u plus
    u's angle), so its mean over a revolution is the law's too."""
    law = PlantCuttingLaw(LINEAR)
    a = np.radians(angle_deg)
    u = np.array([np.cos(a), np.sin(a)])
    chip = RegenerativeChip(law, phase_rad=0.3)
    p = np.array([0.0013, 0.0021, 0.0])
    t = np.arange(240) * (60.0 / CUTTER.spindle_rpm / 240)  # a revolution
    w = chip.wrenches(t, p, straight_past(chip, t, p, 0.02, u), WP, cut_length_m=200.0)
    ref = law.tooth_wrenches(t, p, u, WP, 0.3 - a, 0.02, cut_length_m=200.0)
    assert np.abs(ref[:, :3]).max() > 100.0
    np.testing.assert_allclose(w, ref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(w.mean(axis=0), ref.mean(axis=0), rtol=1e-9, atol=1e-9)


def test_a_tool_retreating_faster_than_the_feed_cuts_nothing():
    """The program goes +x; the tool, after cutting along it at 20 mm/s,
    goes back (-x) at 30 mm/s for a revolution: every tooth that the law's
    immersion engages has a negative chip and has left the cut, and the
    trailing teeth meet only the surface the cutter left on its way in:
    the wrench is zero; at rest for a revolution too (runout alone leaves
    no chip: the tooth's own last pass is as deep)."""
    law = PlantCuttingLaw(LINEAR)
    chip = RegenerativeChip(law)
    p = np.array([0.0013, 0.0021, 0.0])
    rev = 60.0 / CUTTER.spindle_rpm
    t = np.arange(60) * (rev / 60)
    for feed in (-0.03, 0.0):
        past = straight_past(chip, t, p, feed, (1.0, 0.0), since_s=rev, before_m_per_s=0.02)
        w, (theta, depth, h) = chip.wrenches(t, p, past, WP, detail=True)
        engaged, out = chip.out_of_cut(theta, depth, h, (1.0, 0.0), 0.02)
        assert engaged > 100 and out == engaged
        assert np.abs(w).max() == 0.0
    w, (theta, depth, h) = chip.wrenches(t, p, straight_past(chip, t, p, 0.02, (1.0, 0.0)), WP, detail=True)
    assert np.abs(w[:, :3]).max() > 100.0  # (the same tool moving forward cuts, every engaged tooth in the cut)
    engaged, out = chip.out_of_cut(theta, depth, h, (1.0, 0.0), 0.02)
    assert engaged > 100 and out == 0


@pytest.fixture(scope="module")
def arm(robot):
    return arm_at_pose(robot)


def test_the_chip_turns_with_the_tools_motion_with_the_regenerative_option(arm):
    """tests/test_plant_cutting.py's expected failure with the option: the
    program runs along +x, the tool moves at 30 degrees to it at 20 mm/s
    (a tool pushed off its path).  The regenerative source's wrench, over
    the last revolution of its updates (every 0.25 ms), is the law's
    revolution average along the tool's motion at its speed, not along
    the program's."""
    kin, tool, q0 = arm
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    law = PlantCuttingLaw(LINEAR)
    path = PlannedPath([p0 - [0.1, 0, 0], p0 + [0.1, 0, 0]], 0.02)
    wp = Workpiece.from_boxes([[p0[0] - 0.2, p0[0] + 0.2, p0[1] - 0.2, p0[1] + 0.2, p0[2] + 0.003]])
    src = RegenerativeForceSource(force_model=law, workpiece=wp, path=path, kinematics=kin, tool_point_m=tool,
                                  period_s=STEP_S, spindle_body_index=BodyIndex(7), mode="tooth")
    a = np.radians(30.0)
    way = np.array([np.cos(a), np.sin(a), 0.0])
    rev = int(round(60.0 / CUTTER.spindle_rpm / STEP_S))  # updates per revolution
    times = 5.0 + STEP_S * np.arange(2 * rev)
    sim = Simulator(src)
    ctx = sim.get_mutable_context()
    ctx.SetTime(times[0] - 1e-9)
    held = []
    for t in times:
        src.get_input_port().FixValue(ctx, moved(kin, q0, 0.02 * (t - times[-1]) * way))
        sim.AdvanceTo(t + 1e-6)
        held.append(ctx.get_discrete_state(int(src._w)).CopyToVector())
    w = np.mean(held[-rev:], axis=0)
    _, p = kin.flange_rotation_and_tool_point(moved(kin, q0, np.zeros(3)))
    tool_way = law.average_wrench(p, way[:2], wp, 0.02)
    path_way = law.average_wrench(p, (1.0, 0.0), wp, 0.02 * np.cos(a))
    assert np.linalg.norm(tool_way[:3] - path_way[:3]) > 0.2 * np.linalg.norm(path_way[:3])
    np.testing.assert_allclose(w[:3], tool_way[:3], rtol=0.03, atol=1.0)


def _refusal(sc, call):
    with pytest.raises(InputError) as e:
        call(sc)
    msg = str(e.value)
    assert "\n" not in msg, msg
    return msg


def test_the_option_without_resolved_teeth_is_refused(robot):
    """cutting.chip: regenerative with the averaged force: refused by the
    scenario's check, naming the key; with the tooth-resolved force at
    2 ms: refused by the plant-step check, naming 0.25 ms; at 0.25 ms it
    builds."""
    base = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    sc = copy.deepcopy(base)
    sc.cutting.chip = "regenerative"
    msg = _refusal(sc, check_scenario)
    assert "cutting.chip" in msg and "cutting.mode: tooth" in msg, msg
    sc.cutting.mode = "tooth"
    sc.plant_config.time_step = 0.002
    msg = _refusal(sc, lambda s: check_plant_step(s, robot))
    assert "cutting.chip: regenerative" in msg and "2 ms" in msg and "plant_config.time_step: 0.00025" in msg, msg
    sc.plant_config.time_step = 0.00025
    check_plant_step(sc, robot)
