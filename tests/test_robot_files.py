"""Robot files of your own and the commands around the library: bad robot
files (one line naming file and key, exit status 2, nothing written),
`robstiff robots`, `robstiff fk`, --robot in the commands, the URDF cache,
make-urdf, and the controller conventions in the commands' output."""

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from independent_chains import fk_urdf

from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DEFAULT_ROBOT_YAML, MODELS_DIR, robot_file


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def write_robot(tmp_path, mutate, base=DEFAULT_ROBOT_YAML, name="robot.yaml"):
    doc = yaml.safe_load(Path(base).read_text())
    mutate(doc)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return path


def _zero_lengths(d):
    d["dh"].update(d_mm=[0] * 6, a_mm=[0] * 6)


def _coincident_axes(d):
    # axes 2 and 3 on one line (no lower arm), axis 4 along them: joints 2-4 move alike
    d["dh"].update(a_mm=[188.0, 0.0, 0.0, 0.0, 0.0, 0.0], alpha_deg=[-90, 0, 0, -90, 90, 0], d_mm=[900, 0, 0, 0, 0, 200])


BAD = [
    ("wrong joint count", lambda d: d["dh"].update(alpha_deg=[0, 0, 0, 0, 0]), "dh.alpha_deg", "expected 6 numbers, got 5"),
    ("missing key", lambda d: d.pop("joint_limits"), "joint_limits", "missing"),
    ("unknown key", lambda d: d.update(stiffnes=1), "stiffnes", "unknown key"),
    ("unknown convention", lambda d: d.update(convention="hartenberg"), "convention", "unknown convention 'hartenberg'"),
    ("zero lengths", _zero_lengths, "dh", "every link length (a_mm, d_mm) is zero"),
    ("singular chain", _coincident_axes, "dh", "the kinematic table is singular"),
    ("negative mass", lambda d: d["links"][3].update(mass_kg=-50.0), "links[3].mass_kg", "-50 is outside the allowed range [0.01, 20000] kg"),
    ("non-physical inertia", lambda d: d["links"][2].update(inertia_kgm2=[1.0, 1.0, 5.0, 0, 0, 0]),
     "links[2].inertia_kgm2", "not a physical inertia tensor"),
    ("lower above upper", lambda d: d["joint_limits"].update(lower_deg=[-180, 80, -28, -300, -120, -300]),
     "joint_limits.lower_deg", "joint 2: lower 80 >= upper 70 deg: the lower limit must be below the upper (swapped?"),
    ("limits swapped", lambda d: d["joint_limits"].update(lower_deg=[-180, 70, -28, -300, -120, -300],
                                                          upper_deg=[180, -70, 105, 300, 120, 300]),
     "joint_limits.lower_deg", "joint 2: lower 70 >= upper -70 deg: the lower limit must be below the upper (swapped?"),
    ("stiffness in kN*m/rad", lambda d: d.update(joint_stiffness_Nm_per_rad=[1500, 1100, 800, 300, 300, 200]),
     "joint_stiffness_Nm_per_rad", "joint 3: 800 is outside the allowed range [1000, 1e+09] N*m/rad (a small "
     "cobot's wrist ~1e3; the stiffest large-robot axis ~1e7; values in kN*m/rad are 1000 times too small)"),
    ("sign not +-1", lambda d: d.update(controller={"sign": [1, 2, 1, 1, 1, 1]}), "controller.sign",
     "must be +1 or -1"),
    ("singular coupling", lambda d: d.update(controller={"sign": [1, 1, 1, 1, 1, 1],
                                                         "coupling": [{"joint": 3, "from": 2, "factor": 1.0},
                                                                      {"joint": 2, "from": 3, "factor": 1.0}]}),
     "controller.coupling", "singular"),
    ("coupling to itself", lambda d: d.update(controller={"coupling": [{"joint": 3, "from": 3, "factor": 1.0}]}),
     "controller.coupling[0].from", "cannot be coupled to itself"),
    ("negative stiffness", lambda d: d.update(joint_stiffness_Nm_per_rad=[1e6, 1e6, -1e6, 1e5, 1e5, 1e5]),
     "joint_stiffness_Nm_per_rad", "joint 3: -1e+06 is outside the allowed range [1000, 1e+09] N*m/rad"),
]


@pytest.mark.parametrize("what, mutate, key, message", BAD, ids=[b[0] for b in BAD])
def test_bad_robot_file_is_one_line_naming_file_and_key(capsys, tmp_path, what, mutate, key, message):
    path = write_robot(tmp_path, mutate)
    out = tmp_path / "out.json"
    code, stdout, err = run_cli(capsys, "fk", "0", "0", "0", "0", "30", "0", "--robot", path, "--json", out)
    assert code == 2, (stdout, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert str(path) in err and f"key '{key}'" in err and message in err, err
    assert not out.exists()  # nothing written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.yaml"]


def test_angles_outside_the_robots_ranges(capsys, tmp_path):
    out = tmp_path / "s.json"
    # A2 = 0 is outside the KUKA's -140..-5 (fine on the IRB6400)
    code, _, err = run_cli(capsys, "stiffness", "0", "0", "90", "0", "30", "0", "--robot", "kr240_r2900", "--json", out)
    assert code == 2 and "q2 = 0 deg is outside the joint limit [-140, -5] deg of kr240_r2900" in err
    assert not out.exists()
    assert run_cli(capsys, "stiffness", "0", "-60", "90", "0", "30", "0", "--robot", "kr240_r2900", "--json", out)[0] == 0


def test_missing_tool_point_where_one_is_needed(capsys, tmp_path):
    path = write_robot(tmp_path, lambda d: d["payload"].pop("tool_point_mm"))
    out = tmp_path / "s.json"
    code, _, err = run_cli(capsys, "stiffness", "0", "10", "20", "0", "30", "0", "--robot", path, "--json", out)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"{path}: key 'payload.tool_point_mm': missing" in err and "--tool" in err
    assert not out.exists()
    # with --tool it is not needed; fk never needs one (the flange)
    assert run_cli(capsys, "stiffness", "0", "10", "20", "0", "30", "0", "--robot", path, "--tool", "0,0,300")[0] == 0
    assert run_cli(capsys, "fk", "0", "10", "20", "0", "30", "0", "--robot", path)[0] == 0


def test_unknown_robot_name(capsys):
    code, _, err = run_cli(capsys, "fk", "0", "0", "0", "0", "0", "0", "--robot", "irb9999")
    assert code == 2 and "--robot irb9999: not a library robot (irb6400, irb6640, kr240_r2900, r2000ic_165f)" in err


def test_robots_lists_the_library(capsys, tmp_path):
    out = tmp_path / "robots.json"
    code, text, _ = run_cli(capsys, "robots", "--json", out)
    assert code == 0
    rows = json.loads(out.read_text())["robots"]
    assert [r["name"] for r in rows] == ["irb6400", "irb6640", "kr240_r2900", "r2000ic_165f"]
    for r in rows:
        assert {"name", "manufacturer", "convention", "source"} <= set(r)
        assert Path(r["file"]).parent == MODELS_DIR
    assert {r["manufacturer"] for r in rows} == {"ABB", "KUKA", "FANUC"}
    assert "modified_dh" in text and "coupled joints" in text


@pytest.mark.parametrize("name, q", [("kr240_r2900", [20, -70, 100, 30, 40, -60]),
                                     ("r2000ic_165f", [-15, 20, -30, 45, -60, 90]),
                                     ("irb6640", [10, 20, 10, -40, 50, 30])])
def test_fk_command_against_the_published_description(capsys, name, q):
    code, out, err = run_cli(capsys, "fk", *q, "--robot", name, "--tool", "10,-5,350", "--json", "-")
    assert code == 0, err
    rep = json.loads(out)
    p, R = fk_urdf(name, q, (10.0, -5.0, 350.0))
    np.testing.assert_allclose(rep["position_mm"], p, atol=1e-6)
    np.testing.assert_allclose(rep["rotation"], R, atol=1e-12)
    assert rep["q_deg"] == q and rep["robot"] == name


def test_stiffness_keeps_its_keys_for_every_robot(capsys):
    base = None
    for name, q in (("irb6400", [0, 13.62, 21.95, 0, 54.43, 0]), ("kr240_r2900", [0, -61.68, 107.73, 0, 43.96, 0]),
                    ("r2000ic_165f", [0, 17.28, -40.57, 0, -49.43, 180]), ("irb6640", [0, 20.42, 24.06, 0, 45.52, 0])):
        code, out, err = run_cli(capsys, "stiffness", *q, "--robot", name, "--json", "-")
        assert code == 0, err
        rep = json.loads(out)
        keys = set(rep)
        assert {"position_mm", "jacobian", "compliance_mm_per_N", "tool_mm"} <= keys
        assert base is None or keys == base
        base = keys
        # default tool: the robot file's, the reference machining point (to 0.1 mm: the angles are rounded)
        robot = load_robot(name)
        np.testing.assert_allclose(rep["tool_mm"], robot.payload.tool_point_m * 1e3)
        np.testing.assert_allclose(rep["position_mm"], robot.workspace.reference_tool_point_m * 1e3, atol=2.0)


def test_the_urdf_goes_to_the_cache_and_a_stale_copy_is_rewritten(tmp_path, monkeypatch):
    from robstiff_drake.plant import CACHE_ENV, check_plant_matches, make_robot_plant, robot_urdf

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    robot = load_robot("r2000ic_165f")
    path = robot_urdf(robot)
    assert path.parent == tmp_path / "cache" and path.name.startswith("r2000ic_165f-")
    assert oct(path.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    text = path.read_text()
    path.write_text(text.replace('xyz="0.312', 'xyz="0.412'))  # someone edits the cached copy
    assert robot_urdf(robot) == path and path.read_text() == text
    plant, _ = make_robot_plant(robot)
    check_plant_matches(plant, robot)
    # a plant that is not the robot file's (here: the IRB 6640's URDF with the FANUC's kinematics) is refused
    other = load_robot("irb6640")
    with pytest.raises(InputError, match="does not match its robot file"):
        check_plant_matches(make_robot_plant(other)[0], replace(other, dh=robot.dh))
    assert not list(MODELS_DIR.rglob("*.urdf"))  # nothing was ever written into the package


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_make_urdf_writes_a_folder_and_checks_it(capsys, tmp_path):
    out = tmp_path / "urdf"
    code, text, err = run_cli(capsys, "make-urdf", "--robot", "kr240_r2900", "--out", out)
    assert code == 0, err
    urdf = out / "robstiff_kr240_r2900" / "urdf" / "kr240_r2900.urdf"
    assert urdf.exists() and (out / "robstiff_kr240_r2900" / "package.xml").exists()
    assert run_cli(capsys, "make-urdf", "--robot", "kr240_r2900", "--out", out, "--check")[0] == 0
    urdf.write_text(urdf.read_text() + "<!-- edited -->\n")
    code, _, err = run_cli(capsys, "make-urdf", "--robot", "kr240_r2900", "--out", out, "--check")
    assert code == 2 and "out of date" in err
    # never into the package's robot folder
    code, _, err = run_cli(capsys, "make-urdf", "--robot", "irb6640", "--out", MODELS_DIR)
    assert code == 2 and "inside the package's data folder" in err
    assert not (MODELS_DIR / "robstiff_irb6640").exists()


def test_a_robot_file_of_your_own_with_every_convention(tmp_path, rng):
    """A modified-DH file with a base offset (a0, alpha0), sign flips, an offset
    and a coupling: the model agrees with Craig's formula typed in here."""
    import math

    from independent_chains import craig_link, matmul4

    from robstiff_drake.model import kinematics as kin

    rows = [(0.0, 150.0, 700.0), (-90.0, 300.0, 0.0), (0.0, 1000.0, 0.0), (-90.0, 200.0, 1100.0), (90.0, 0.0, 0.0),
            (-90.0, 0.0, 180.0)]
    doc = yaml.safe_load(robot_file("r2000ic_165f").read_text())
    doc["name"] = "mine"
    doc["dh"] = {"alpha_deg": [r[0] for r in rows], "a_mm": [r[1] for r in rows], "d_mm": [r[2] for r in rows],
                 "home_deg": [5.0, -90.0, 0.0, 0.0, 0.0, 10.0]}
    doc["controller"] = {"sign": [-1, 1, -1, -1, 1, -1], "offset_deg": [0.0, 0.0, 0.0, 0.0, 20.0, 0.0],
                         "coupling": [{"joint": 3, "from": 2, "factor": -1.0}]}
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(doc))
    robot = load_robot(str(path))
    assert robot.dh.base is not None  # a0 = 150 mm: a base transform
    for _ in range(20):
        J = rng.uniform(-60, 60, 6)
        theta = [-J[0] + 5.0, J[1] - 90.0, -J[2] - J[1], -J[3], J[4] + 20.0, -J[5] + 10.0]
        T = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
        for (al, a, d), th in zip(rows, theta):
            T = matmul4(T, craig_link(math.radians(al), a, math.radians(th), d))
        mine = kin.frames(robot.dh, robot.joint_rad(J))[6]
        np.testing.assert_allclose(mine[:3, 3] * 1e3, [T[i][3] for i in range(3)], atol=1e-6)
        np.testing.assert_allclose(mine[:3, :3], [row[:3] for row in T[:3]], atol=1e-12)
