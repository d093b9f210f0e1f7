"""`robstiff import-urdf` on URDFs as a CAD export or ROS-Industrial writes
them: joint 1's axis a few mm and a fraction of a degree off the base frame
(absorbed: the robot file's base on the axis, the offset said), `tool0`
with its x axis along joint 6 (KUKA's convention in ROS-Industrial's URDFs,
recognised), the controller's sign/offset map from the template or
--controller-map (the controller's angles then work), and beyond what is
absorbed, one line naming the joint, its line and what to change."""

import re

import numpy as np

from robstiff_drake.commands.main import main
from robstiff_drake.commands.make_urdf import wanted_files
from robstiff_drake.io import write_atomic
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot


def cad_urdf(tmp_path, shift_xyz="0.0026 0.001 0", tilt_rpy="0.003 -0.002 0", tool0=True):
    """kr240_r2900's URDF (make-urdf) edited as a CAD export: joint 1's
    origin moved and turned, the flange frame renamed tool0 with its x axis
    along joint 6."""
    robot = load_robot("kr240_r2900")
    files = wanted_files(robot, tmp_path / "made")
    for p, text in files.items():
        write_atomic(p, text)
    text = next(p for p in files if p.suffix == ".urdf").read_text()
    new = re.sub(r'(<child link="turret"/>\s*)<origin xyz="0 0 0" rpy="0 -0 0"/>',
                 rf'\1<origin xyz="{shift_xyz}" rpy="{tilt_rpy}"/>', text)
    assert new != text or (shift_xyz, tilt_rpy) == ("0 0 0", "0 -0 0")
    if tool0:
        text = new
        new = re.sub(r'<child link="flange"/>(\s*)<origin xyz="0 0 0.23999999999999999" rpy="0 -0 0"/>',
                     r'<child link="tool0"/>\1<origin xyz="0 0 0.23999999999999999" rpy="0 -1.5707963267948966 0"/>',
                     text)
        new = new.replace('<link name="flange"/>', '<link name="tool0"/>').replace('<parent link="flange"/>',
                                                                                   '<parent link="tool0"/>')
        assert new.count("tool0") == 3
    out = tmp_path / "kr_cad.urdf"
    out.write_text(new)
    return out, robot


def run(capsys, *argv):
    capsys.readouterr()
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


def test_a_cad_export_with_tool0_imports_and_takes_the_controllers_angles(tmp_path, capsys):
    urdf, shipped = cad_urdf(tmp_path)
    out = tmp_path / "kr.yaml"
    code, text, err = run(capsys, "import-urdf", urdf, "--out", out, "--template", "kr240_r2900",
                          "--controller-map", "template")
    assert code == 0, err
    said = text + err
    assert "absorbed: joint 1's axis ('joint_1', line" in said and "2.79 mm" in said and "0.207 deg" in said, said
    assert "x axis along joint 6" in said
    imported = load_robot(str(out))
    # the controller's angles (KUKA's A1..A6) give the shipped arm's flange, to the 0.2 deg base tilt's share
    q_ctrl = np.deg2rad([[0, -90, 90, 0, 0, 0], [30, -60, 45, 10, 40, -20]])
    got = kin.tool_position(imported.dh, imported.joint_map.to_model(q_ctrl))
    want = kin.tool_position(shipped.dh, shipped.joint_map.to_model(q_ctrl))
    assert np.abs(got - want).max() < 0.05e-3, np.abs(got - want).max()
    assert main(["fk", "0", "-90", "90", "0", "0", "0", "--robot", str(out)]) == 0
    # the flange frame's z axis runs along joint 6 (tool0's x)
    np.testing.assert_allclose(kin.frames(imported.dh, np.zeros(6))[6, :3, 2],
                               kin.frames(shipped.dh, np.zeros(6))[6, :3, 2], atol=0.01)


def test_an_explicit_controller_map(tmp_path, capsys):
    urdf, shipped = cad_urdf(tmp_path, shift_xyz="0 0 0", tilt_rpy="0 -0 0")
    out = tmp_path / "kr.yaml"
    code, _, err = run(capsys, "import-urdf", urdf, "--out", out, "--template", "kr240_r2900",
                       "--controller-map", "-1,1,1,-1,1,-1:0,0,-90,0,0,0")
    assert code == 0, err
    imported = load_robot(str(out))
    q_ctrl = np.deg2rad(np.random.default_rng(1).uniform(-40, 40, size=(20, 6))) + np.deg2rad([0, -70, 60, 0, 0, 0])
    np.testing.assert_allclose(kin.tool_position(imported.dh, imported.joint_map.to_model(q_ctrl)),
                               kin.tool_position(shipped.dh, shipped.joint_map.to_model(q_ctrl)), atol=1e-12)
    np.testing.assert_allclose(imported.q_lower_rad, shipped.q_lower_rad, atol=1e-12)
    for bad, word in (("1,1,1,1,1,2:0,0,0,0,0,0", "must each be 1 or -1"), ("1,1,1:0,0,0", "6 numbers"),
                      ("nonsense", "expected 'template'")):
        code, _, err = run(capsys, "import-urdf", urdf, "--out", tmp_path / "x.yaml", "--controller-map", bad)
        assert code == 2 and word in err and err.count("\n") == 1, err
    assert not (tmp_path / "x.yaml").exists()


def test_beyond_a_cad_offset_is_one_plain_line(tmp_path, capsys):
    urdf, _ = cad_urdf(tmp_path, shift_xyz="0.005 0.011 0", tool0=False)
    code, _, err = run(capsys, "import-urdf", urdf, "--out", tmp_path / "x.yaml")
    assert code == 2 and err.count("\n") == 1, err
    assert "joint 1 ('joint_1', line" in err and "12.1 mm" in err and "<origin" in err, err
    # an axis that meets the base x axis is a modified DH base row, however far: no correction, no refusal
    urdf, shipped = cad_urdf(tmp_path, shift_xyz="0.012 0 0", tilt_rpy="0 -0 0", tool0=False)
    code, out, err = run(capsys, "import-urdf", urdf, "--out", tmp_path / "y.yaml")
    assert code == 0 and "absorbed" not in out + err, out + err
    assert load_robot(str(tmp_path / "y.yaml")).convention == "modified_dh"


def test_the_title_has_no_unknown_maker(tmp_path, capsys):
    """An imported file's maker is '-': its title is the model alone (not '- kr240_r2900')."""
    urdf, _ = cad_urdf(tmp_path)
    out = tmp_path / "kr.yaml"
    assert run(capsys, "import-urdf", urdf, "--out", out)[0] == 0
    robot = load_robot(str(out))
    assert robot.manufacturer == "-" and robot.title == robot.model == "kr240_r2900"
    assert load_robot("kr240_r2900").title == "KUKA KR 240 R2900-2"
