"""Robot files through the same discipline as scenarios (issue 19, item 4):
duplicated keys refused, every number against its range and unit (file,
line, key, range in one line), values in another unit (metres, radians,
kN*m/rad) refused or warned about, and the physics plausible (masses,
centres of mass, inertias, the first natural mode) with warnings in the
text and the JSON.  The rigid-body quantities behind the checks are
compared with Drake's MultibodyPlant (an independent implementation)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.model import robot_checks, robot_file
from robstiff_drake.model.arm_dynamics import ArmInertia
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DEFAULT_ROBOT_YAML, library_robots

TEXT = DEFAULT_ROBOT_YAML.read_text()
FK = ["fk", "0", "0", "0", "0", "30", "0"]


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def edited(tmp_path, old, new, text=TEXT, name="robot.yaml"):
    assert old in text, old
    p = tmp_path / name
    p.write_text(text.replace(old, new, 1))
    return p


def line_of(path, fragment):
    return next(n for n, ln in enumerate(Path(path).read_text().splitlines(), 1) if fragment in ln)


def refused(capsys, path, *fragments, argv=FK):
    before = Path(path).read_bytes()
    code, out, err = cli(capsys, *argv, "--robot", path)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert Path(path).read_bytes() == before
    return lines[0]


K_LINE = "joint_stiffness_Nm_per_rad: [1.5e6, 1.1e6, 0.8e6, 3.0e5, 3.0e5, 2.0e5]"
TOOL_LINE = "  tool_point_mm: [0.0, 0.0, 350.0]"


def test_the_library_robots_pass_every_check_without_a_warning():
    for name in library_robots():
        assert load_robot(name).warnings == (), name


def test_a_duplicated_key_is_refused_not_silently_replaced(capsys, tmp_path):
    # the case: a second stiffness 1000 times larger was used silently
    p = edited(tmp_path, K_LINE, K_LINE + "\njoint_stiffness_Nm_per_rad: [1.5e9, 1.1e9, 0.8e9, 3.0e8, 3.0e8, 2.0e8]")
    n = line_of(p, K_LINE)
    refused(capsys, p, f"{p}:{n + 1}: duplicated key 'joint_stiffness_Nm_per_rad' (first on line {n})")
    p = edited(tmp_path, "  mass_kg: 40.0\n", "  mass_kg: 40.0\n  mass_kg: 4.0\n", name="payload.yaml")
    refused(capsys, p, "duplicated key 'mass_kg'")


@pytest.mark.parametrize("old, new, fragments", [
    (K_LINE, "joint_stiffness_Nm_per_rad: [1e-300, 1.1e6, 0.8e6, 3.0e5, 3.0e5, 2.0e5]",
     ["key 'joint_stiffness_Nm_per_rad': joint 1: 1e-300 is outside the allowed range [1000, 1e+09] N*m/rad"]),
    (TOOL_LINE, "  tool_point_mm: [0.0, 0.0, 1e300]",
     ["key 'payload.tool_point_mm': z: 1e+300 is outside the allowed range [-5000, 5000] mm"]),
    (K_LINE, "joint_stiffness_Nm_per_rad: [a, b, c, d, e, f]",
     ["key 'joint_stiffness_Nm_per_rad': joint 1: expected a number in N*m/rad, got 'a'"]),
    (K_LINE, "joint_stiffness_Nm_per_rad: {a: 1}", ["expected 6 numbers in N*m/rad, got {'a': 1}"]),
    (K_LINE, "joint_stiffness_Nm_per_rad: [[1, 2], [3], 4, 5, 6, 7]", ["expected 6 numbers in N*m/rad, got [[1, 2]"]),
    (K_LINE, "joint_stiffness_Nm_per_rad: [١٥٠٠٠٠٠, 1.1e6, 0.8e6, 3.0e5, 3.0e5, 2.0e5]",
     ["joint 1: expected a number in N*m/rad"]),
    ("    mass_kg: 220.0", "    mass_kg: 23000.0",
     ["key 'links[2].mass_kg': 23000 is outside the allowed range [0.01, 20000] kg"]),
    ("  mass_kg: 40.0\n", "  mass_kg: .nan\n", ["key 'payload.mass_kg': expected a finite number, got nan"]),
    ("    com_mm: [475.0, 0.0, 0.0]", "    com_mm: [475.0, 0.0, true]", ["links[2].com_mm': z: expected a number in mm"]),
    ("  x_mm: [1200.0, 2000.0]", "  x_mm: [1200.0, 2e6]",
     ["key 'machining_workspace.x_mm': max: 2e+06 is outside the allowed range [-10000, 10000] mm"]),
])
def test_every_number_is_checked_against_its_range_and_unit(capsys, tmp_path, old, new, fragments):
    p = edited(tmp_path, old, new)
    n = line_of(p, new.strip().splitlines()[0])
    refused(capsys, p, f"{p}:{n}: ", *fragments)


@pytest.mark.parametrize("old, new, fragment", [
    ("  d_mm:      [900.0,   0.0,   0.0, 1300.0,  0.0, 200.0]", "  d_mm: [0.9, 0, 0, 1.3, 0, 0.2]",
     None),
    ("  alpha_deg: [-90.0,   0.0, -90.0,  -90.0, 90.0,   0.0]",
     "  alpha_deg: [-1.5708, 0.0, -1.5708, -1.5708, 1.5708, 0.0]",
     "key 'dh.alpha_deg': joint 1: -1.5708 looks like radians (-90 deg); write degrees"),
    ("  lower_deg: [-180.0, -70.0, -28.0, -300.0, -120.0, -300.0]\n  upper_deg: [ 180.0,  70.0, 105.0,  300.0,  120.0,  300.0]",
     "  lower_deg: [-3.14, -1.22, -0.49, -5.24, -2.09, -5.24]\n  upper_deg: [3.14, 1.22, 1.83, 5.24, 2.09, 5.24]",
     "are these radians? (write degrees)"),
    # axis speeds in rad/s (1.75 rad/s = 100 deg/s): 1.75 deg/s is in the range but no robot's axis
    ("  speed_deg_per_s: [100.0, 90.0, 90.0, 170.0, 140.0, 190.0]",
     "  speed_deg_per_s: [1.75, 1.57, 1.57, 2.97, 2.44, 3.32]",
     "key 'joint_limits.speed_deg_per_s': every axis speed is at most 3.32 deg/s: data sheets give 50-1,000 deg/s; "
     "are these rad/s? (write deg/s)"),
    # kN*m/rad: joints 4-6 fall below the range; here all are within it and the sag decides
    (K_LINE, "joint_stiffness_Nm_per_rad: [1.5e3, 1.1e3, 1.0e3, 1.0e3, 1.0e3, 1.0e3]",
     "under its own weight at the reference machining pose: no arm holds itself so softly; are the stiffnesses in "
     "kN*m/rad?"),
])
def test_values_in_another_unit_are_refused(capsys, tmp_path, old, new, fragment):
    if fragment is None:  # lengths in metres: both a_mm and d_mm
        p = edited(tmp_path, old, new, text=TEXT.replace("  a_mm:      [188.0, 950.0, 225.0,    0.0,  0.0,   0.0]",
                                                         "  a_mm: [0.188, 0.95, 0.225, 0, 0, 0]"))
        fragment = "the longest link length (a_mm, d_mm) is 1.3 mm"
    else:
        p = edited(tmp_path, old, new)
    refused(capsys, p, fragment)


def _warnings(capsys, path, argv=FK):
    """(JSON warnings, stderr) of fk --json - on a robot file that loads."""
    code, out, err = cli(capsys, *argv, "--robot", path, "--json", "-")
    assert code == 0, err
    warnings = json.loads(out)["warnings"]
    printed = [ln[len("robstiff: warning: "):] for ln in err.splitlines() if ln.startswith("robstiff: warning: ")]
    assert printed == warnings  # the same lines, in the text and in the JSON
    return warnings


@pytest.mark.parametrize("old, new, pattern", [
    # the cases: a lower-arm centre of mass 4.87 m out on its link; a link far too heavy for its size
    ("    com_mm: [475.0, 0.0, 0.0]", "    com_mm: [4870.0, 0.0, 0.0]",
     r"links\[2\] \(lower_arm\): the centre of mass \[4870.0, 0.0, 0.0\] mm is 3920 mm from the link's segment"),
    ("    mass_kg: 220.0", "    mass_kg: 5000.0", r"links\[2\] \(lower_arm\): 5000 kg in a cylinder .* kg/m\^3, outside"),
    ("    box_mm: [450.0, 600.0, 450.0]", "    box_mm: [450.0, 600.0, 450.0]\n    inertia_kgm2: [400, 300, 400, 0, 0, 0]",
     r"links\[3\] \(upper_arm\): inertia_kgm2 is [0-9.e+]+ times that of the link's box"),
    (K_LINE, "joint_stiffness_Nm_per_rad: [1.5e5, 6.0e4, 4.0e4, 3.0e4, 3.0e4, 2.0e4]",
     r"the first natural frequency at the reference machining pose is 1.\d+ Hz .*outside the 2-40 Hz"),
    (K_LINE, "joint_stiffness_Nm_per_rad: [1e9, 1e9, 1e9, 1e9, 1e9, 1e9]",
     r"the first natural frequency .* is 1\d\d Hz"),
    (TOOL_LINE, "  tool_point_mm: [0.0, 0.0, 0.35]",
     r"payload.tool_point_mm \(0, 0, 0.35\): the tool point is 0.35 mm from the flange; is it in metres\?"),
])
def test_implausible_physics_is_a_warning_in_the_text_and_the_json(capsys, tmp_path, old, new, pattern):
    p = edited(tmp_path, old, new)
    warnings = _warnings(capsys, p)
    assert any(re.search(pattern, w) for w in warnings), warnings
    assert all(w.startswith(str(p)) for w in warnings)
    assert load_robot(p).warnings == tuple(warnings)


def test_a_nonphysical_inertia_is_refused(capsys, tmp_path):
    p = edited(tmp_path, "    box_mm: [450.0, 600.0, 450.0]",
               "    box_mm: [450.0, 600.0, 450.0]\n    inertia_kgm2: [1.0, 1.0, 5.0, 0, 0, 0]")
    refused(capsys, p, f"{p}:{line_of(p, '    inertia_kgm2')}: key 'links[3].inertia_kgm2': not a physical inertia "
                       "tensor")


def test_the_rigid_body_checks_agree_with_drake():
    """The one numpy model of the arm's rigid bodies (model/arm_dynamics.ArmInertia:
    the preview compensator's, the loop check's and robot_checks') against
    Drake's MultibodyPlant of every library robot at random poses within its
    limits: mass matrix, gravity torques, and robot_checks' first modes."""
    from robstiff_drake.diagrams.station import controller_model, modal_frequencies_hz

    rng = np.random.default_rng(7)
    worst = 0.0  # the largest mass-matrix difference, over the largest entry
    for name in library_robots():
        robot = load_robot(name)
        arm = ArmInertia(robot)
        plant = controller_model(robot)
        ctx = plant.CreateDefaultContext()
        for q in rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(3, 6)):
            plant.SetPositions(ctx, q)
            M = plant.CalcMassMatrix(ctx)
            worst = max(worst, float(np.abs(arm.mass_matrix(q) - M).max() / np.abs(M).max()))
            np.testing.assert_allclose(arm.mass_matrix(q), M, rtol=0, atol=1e-9 * np.abs(M).max())
            np.testing.assert_allclose(arm.gravity_torques(q), plant.CalcGravityGeneralizedForces(ctx),
                                       rtol=0, atol=1e-8)
            np.testing.assert_allclose(robot_checks.first_modes_hz(robot, q),
                                       modal_frequencies_hz(M, robot.joint_stiffness_Nm_per_rad), rtol=1e-9)
    print(f"{len(library_robots())} library robots: ArmInertia's mass matrix differs from Drake's CalcMassMatrix "
          f"by at most {worst:.2g} of its largest entry")


def test_a_key_added_to_the_table_is_checked_with_its_range_and_unit(monkeypatch, tmp_path):
    """How another change adds a key: one line in robot_file.KEYS (a made-up key,
    not one the table already has)."""
    monkeypatch.setitem(robot_file.KEYS, "joint_limits.jerk_deg_per_s3",
                        robot_file.Key("vector", "deg/s^3", 1.0, 1000.0, 6, required=False, names=robot_file.JOINTS))
    assert load_robot(DEFAULT_ROBOT_YAML).name == "irb6400"  # optional: files without it still load
    p = edited(tmp_path, "  upper_deg: [ 180.0,  70.0, 105.0,  300.0,  120.0,  300.0]",
               "  upper_deg: [ 180.0,  70.0, 105.0,  300.0,  120.0,  300.0]\n"
               "  jerk_deg_per_s3: [100, 100, 100, 200, 5000, 200]")
    with pytest.raises(InputError, match=rf"robot.yaml:{line_of(p, 'jerk_deg_per_s3')}: key "
                                         r"'joint_limits.jerk_deg_per_s3': joint 5: 5000 is outside the allowed range "
                                         r"\[1, 1000\] deg/s\^3"):
        load_robot(p)


def test_a_tool_point_in_metres_is_warned_at_its_line(capsys, tmp_path):
    """The metres warning names the file's line, as the errors do (it named
    the file alone: a user's hand-written file had to be searched)."""
    p = edited(tmp_path, TOOL_LINE, "  tool_point_mm: [0.0, 0.0, 0.35]")
    warnings = _warnings(capsys, p)
    want = f"{p}:{line_of(p, '  tool_point_mm')}: payload.tool_point_mm (0, 0, 0.35)"
    assert any(w.startswith(f"robstiff: warning: {want}") or w.startswith(want) for w in warnings), warnings
