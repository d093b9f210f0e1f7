"""``robstiff import-urdf``: the library's robots, written as URDFs by
``robstiff make-urdf`` and read back with Drake's parser, give robot files
whose kinematics are the shipped files' (the flange to 1e-9 mm at random
joint angles, whatever DH frames the import chose) and whose links have the
shipped masses and inertias (compared in the base frame, where the link
frames' choice does not matter); bad input is one line, exit 2."""

import re

import numpy as np
import pytest

from robstiff_drake.commands.import_urdf import world_inertias
from robstiff_drake.commands.main import main
from robstiff_drake.commands.make_urdf import wanted_files
from robstiff_drake.io import write_atomic
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import library_robots


def made_urdf(tmp_path, name):
    robot = load_robot(name)
    files = wanted_files(robot, tmp_path)
    for p, text in files.items():
        write_atomic(p, text)
    return next(p for p in files if p.suffix == ".urdf"), robot


def run(capsys, *argv):
    capsys.readouterr()
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("name", library_robots())
def test_an_imported_urdf_is_the_robot_file_it_came_from(tmp_path, capsys, name):
    urdf, shipped = made_urdf(tmp_path, name)
    out = tmp_path / f"imported_{name}.yaml"
    code, _, err = run(capsys, "import-urdf", urdf, "--out", out, "--template", name)
    assert code == 0, err
    imported = load_robot(str(out))
    rng = np.random.default_rng(7)
    q = rng.uniform(*shipped.model_limits_rad, size=(50, 6))  # the URDF's joint angles are the model's
    assert np.abs(kin.tool_position(imported.dh, q) - kin.tool_position(shipped.dh, q)).max() < 1e-12
    np.testing.assert_allclose(kin.frames(imported.dh, q)[:, 6, :3, :3], kin.frames(shipped.dh, q)[:, 6, :3, :3],
                               atol=1e-12)
    np.testing.assert_allclose(imported.model_limits_rad, shipped.model_limits_rad, atol=1e-12)
    assert [link.mass_kg for link in imported.links] == pytest.approx([link.mass_kg for link in shipped.links],
                                                                      rel=1e-14)
    for qk in q[:5]:
        for (m1, c1, I1), (m2, c2, I2) in zip(world_inertias(imported, qk), world_inertias(shipped, qk)):
            np.testing.assert_allclose(c1, c2, atol=1e-12)
            np.testing.assert_allclose(I1, I2, atol=1e-10 * max(1.0, np.abs(I2).max()))
    # the spindle make-urdf writes comes back as the payload
    assert imported.payload.mass_kg == pytest.approx(shipped.payload.mass_kg, rel=1e-14)
    np.testing.assert_allclose(imported.payload.com_m, shipped.payload.com_m, atol=1e-12)
    code, out, err = run(capsys, "import-urdf", urdf, "--out", tmp_path / "again.yaml", "--template", name)
    assert "flange within" in out + err


def _edit(urdf, pattern, replacement, tmp_path, count=1):
    text = urdf.read_text()
    new = re.sub(pattern, replacement, text, count=count, flags=re.S)
    assert new != text
    p = tmp_path / "edited.urdf"
    p.write_text(new)
    return p


@pytest.mark.parametrize("edit, message", [
    (None, "cannot read"),
    ((r"<robot ", "<robt "), "not well-formed XML"),
    ((r'<joint name="joint_6" type="revolute">', '<joint name="joint_6" type="fixed">'), "5 revolute joints"),
    ((r'(<joint name="joint_3"[^>]*>.*?)<limit [^>]*/>', r"\1"), "no position limits"),
    ((r'(<link name="wrist">\s*)<inertial>.*?</inertial>', r"\1"), "has no mass"),
])
def test_bad_urdfs_are_one_line(tmp_path, capsys, edit, message):
    urdf, _ = made_urdf(tmp_path, "irb6400")
    src = tmp_path / "missing.urdf" if edit is None else _edit(urdf, *edit, tmp_path)
    code, _, err = run(capsys, "import-urdf", src, "--out", tmp_path / "x.yaml")
    assert code == 2
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "x.yaml").exists()


def test_the_urdf_is_never_overwritten(tmp_path, capsys):
    urdf, _ = made_urdf(tmp_path, "irb6400")
    before = urdf.read_bytes()
    code, _, err = run(capsys, "import-urdf", urdf, "--out", urdf)
    assert code == 2 and err.count("\n") == 1
    assert urdf.read_bytes() == before


def test_a_balancing_cylinder_that_mimics_a_joint_is_left_out(tmp_path, capsys):
    """ROS-Industrial's ABB URDFs add the axis-2 balancing cylinder as joints
    that mimic joint 2: not part of the chain."""
    urdf, shipped = made_urdf(tmp_path, "irb6400")
    extra = ('<link name="cylinder"><inertial><mass value="5"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" '
             'iyz="0"/></inertial></link><joint name="joint_cylinder" type="continuous"><parent link="turret"/>'
             '<child link="cylinder"/><axis xyz="0 1 0"/><mimic joint="joint_2" multiplier="-0.25"/></joint></robot>')
    p = _edit(urdf, r"</robot>", extra, tmp_path)
    out = tmp_path / "with_cylinder.yaml"
    code, _, err = run(capsys, "import-urdf", p, "--out", out)
    assert code == 0, err
    q = np.zeros(6)
    assert np.abs(kin.tool_position(load_robot(str(out)).dh, q) - kin.tool_position(shipped.dh, q)).max() < 1e-12


@pytest.mark.parametrize("file_name", ['q"uote.urdf', "back\\slash.urdf", "new\nline.urdf", "é ü.urdf"])
def test_any_urdf_file_name_gives_a_robot_file(tmp_path, capsys, file_name):
    """The URDF's file name is written into the robot file (its comment and
    'source:'): a quote, a backslash, a newline or accents in it used to make
    the file unreadable (an error naming a temporary file)."""
    urdf, _ = made_urdf(tmp_path, "irb6400")
    renamed = urdf.with_name(file_name)
    urdf.rename(renamed)
    out = tmp_path / "named.yaml"
    code, _, err = run(capsys, "import-urdf", renamed, "--out", out)
    assert code == 0, err
    import yaml

    assert yaml.safe_load(out.read_text(encoding="utf-8"))["source"] == f"imported from {file_name}"
    load_robot(str(out))


@pytest.mark.parametrize("name", ["a: b", "#x", "it's", "x\ny", "9lives"])
def test_a_bad_name_is_refused_naming_the_option(tmp_path, capsys, name):
    urdf, _ = made_urdf(tmp_path, "irb6400")
    code, _, err = run(capsys, "import-urdf", urdf, "--out", tmp_path / "x.yaml", "--name", name)
    assert code == 2 and err.count("\n") == 1, err
    assert "--name" in err and "letters, digits and _" in err and "tmp" not in err.split("--name")[0], err
    assert not (tmp_path / "x.yaml").exists()


def _line_of(path, needle):
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


@pytest.mark.parametrize("edit, needle, message", [
    # before: ValueError (a traceback)
    ((r'(<joint name="joint_2"[^>]*>.*?)<axis xyz="0 0 1"/>', r'\1<axis xyz="nan 0 1"/>'), 'xyz="nan 0 1"',
     "joint 'joint_2': <axis xyz>"),
    # before: LinAlgError
    ((r'(<joint name="joint_3"[^>]*>.*?)<origin xyz="[^"]*"', r'\1<origin xyz="1e300 0 0"'), 'xyz="1e300 0 0"',
     "joint 'joint_3': <origin xyz '1e300 0 0'>: more than 100 m"),
    # before: exit 1, Drake's "Failure at ... joint.h:159"
    ((r'(<joint name="joint_2"[^>]*>.*?)<limit lower="[^"]*" upper="[^"]*"',
      r'\1<limit lower="1.0" upper="-1.0"'), 'lower="1.0" upper="-1.0"', "the lower limit is above the upper"),
    # before: written as 1 kg, Drake's warning the only trace
    ((r'<mass value="220"/>', '<mass value="-220"/>'), 'value="-220"', "a negative mass"),
    ((r'ixx="2.4750000000000001"', 'ixx="40.0"'), 'ixx="40.0"', "are no rigid body's"),
    ((r'ixx="2.4750000000000001"', 'ixx="-2.5"'), 'ixx="-2.5"', "are no rigid body's"),
], ids=["nan-axis", "huge-origin", "lower-above-upper", "negative-mass", "triangle-inertia", "negative-inertia"])
def test_hostile_urdf_numbers_are_one_line_naming_the_line(tmp_path, capsys, edit, needle, message):
    urdf, _ = made_urdf(tmp_path, "irb6400")
    src = _edit(urdf, *edit, tmp_path)
    code, _, err = run(capsys, "import-urdf", src, "--out", tmp_path / "x.yaml")
    assert code == 2 and err.count("\n") == 1, err
    assert f"{src}:{_line_of(src, needle)}: " in err and message in err, err
    assert not (tmp_path / "x.yaml").exists()


def test_deep_nesting_and_xacro_are_refused(tmp_path, capsys):
    urdf, _ = made_urdf(tmp_path, "irb6400")
    deep = _edit(urdf, r"(<robot [^>]*>)", r"\1" + "<a>" * 5000 + "</a>" * 5000, tmp_path)  # before: RecursionError
    code, _, err = run(capsys, "import-urdf", deep, "--out", tmp_path / "x.yaml")
    assert code == 2 and err.count("\n") == 1 and "nested 33 deep" in err, err
    xacro = tmp_path / "x.urdf"
    xacro.write_text(urdf.read_text().replace("<robot ", '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" ', 1)
                     .replace('<link name="wrist">', '<xacro:include filename="more.xacro"/><link name="wrist">', 1))
    code, _, err = run(capsys, "import-urdf", xacro, "--out", tmp_path / "x.yaml")  # before: the include dropped
    assert code == 2 and err.count("\n") == 1, err
    assert f"{xacro}:{_line_of(xacro, 'xacro:include')}: <xacro:include>: a xacro macro" in err, err
    assert not (tmp_path / "x.yaml").exists()
