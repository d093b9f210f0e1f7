"""A stiffness campaign whose header names its units (identification/
stiffness/header_units.py): converted to deg, mm, N, N*m, mrad, s, so that
a campaign exported in SI units reads as the same campaign written in the
project's units; joints' common names read as q1..q6; a unit a column
cannot take is one line naming the column.  Before, such a file was refused
with "missing column 'q1'" though its header said ``q1 [rad]``."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
from robstiff_drake.model.robot import load_robot
from test_campaign_io import campaign_text

ROBOT = load_robot()
FACTORS = {"q": np.pi / 180.0, "f": 1e-3, "d": 1e-3, "m": 1.0, "r": 1.0}  # deg -> rad, N -> kN, mm -> m


def _in_units(text, header_for):
    """``text`` (a campaign in deg, N, mm) with its header renamed by
    ``header_for(column)`` -> (new name, factor the values are multiplied by)."""
    lines = text.splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    body = [ln.split(",") for ln in lines if not ln.startswith("#")]
    head = body[0]
    new = [header_for(h) for h in head]
    rows = [[c if f is None else repr(float(c) * f) for c, (_, f) in zip(r, new)] for r in body[1:]]
    return "\n".join(comments + [",".join(n for n, _ in new)] + [",".join(r) for r in rows]) + "\n"


def _si(h):
    if h[0] in "qfd" and len(h) == 2:
        unit = {"q": "rad", "f": "kN", "d": "m"}[h[0]]
        return f"{h} [{unit}]", FACTORS[h[0]]
    return h, None


def test_a_campaign_in_si_units_reads_as_the_same_campaign(tmp_path):
    text = campaign_text()
    (tmp_path / "deg.csv").write_text(text)
    (tmp_path / "si.csv").write_text(_in_units(text, _si))
    a = read_stiffness_campaign(tmp_path / "deg.csv", ROBOT)
    b = read_stiffness_campaign(tmp_path / "si.csv", ROBOT)
    np.testing.assert_allclose(b.q_deg, a.q_deg, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b.force_N, a.force_N, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b.disp_mm, a.disp_mm, rtol=1e-12, atol=1e-12)


def test_identify_gives_the_same_stiffness_from_either_file(tmp_path, capsys):
    text = campaign_text()
    (tmp_path / "deg.csv").write_text(text)
    (tmp_path / "si.csv").write_text(_in_units(text, _si))
    assert main(["identify", str(tmp_path / "deg.csv"), "--json", str(tmp_path / "a.json")]) == 0
    assert main(["identify", str(tmp_path / "si.csv"), "--json", str(tmp_path / "b.json")]) == 0
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in "ab")
    np.testing.assert_allclose(b["joint_stiffness_Nm_per_rad"], a["joint_stiffness_Nm_per_rad"], rtol=1e-8)


def test_joint_names_and_suffix_units():
    from robstiff_drake.identification.stiffness.header_units import HeaderUnits, split_unit

    assert split_unit("q1 [rad]") == ("q1", "rad") and split_unit("dx (m)") == ("dx", "m")
    assert split_unit("dx_mm") == ("dx", "mm") and split_unit("t_s") == ("t", "s") and split_unit("q1") == ("q1", None)
    assert split_unit("operator_name") == ("operator_name", None)
    h = HeaderUnits("f.csv")
    assert [h(c) for c in ("J1", "A2", "joint_3", "axis4", "theta5", "Q6")] == ["q1", "q2", "q3", "q4", "q5", "q6"]
    assert h("Fx [kN]") == "fx" and h.scale("fx") == (1000.0, "kn")
    assert h("t_s") == "t_s" and h.scale("t_s") == (1.0, "s")
    assert h("pose") == "pose" and h("operator") == "operator" and h.scale("q1") == (1.0, None)
    assert h("Time [min]") == "t_s" and h.scale("t_s") == (60.0, "min")
    assert h("Time") == "time" and h("t") == "t"  # a clock's column ('10:32:15') stays an extra one, ignored


def test_a_unit_a_column_cannot_take_names_the_column(tmp_path, capsys):
    text = _in_units(campaign_text(), lambda h: ("dx [N]", 1.0) if h == "dx" else (h, None))
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(InputError, match=r"bad.csv: header column 'dx \[n\]': unit 'n' of dx not understood"):
        read_stiffness_campaign(tmp_path / "bad.csv", ROBOT)
    assert main(["identify", str(tmp_path / "bad.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "not understood (known: cm, in, inch, m, mm, um)" in err


def test_the_plausible_range_is_checked_in_the_campaigns_units(tmp_path):
    """dx [m] of 0.5 is 500 mm, beyond the 100 mm a loaded tool moves: refused, naming both."""
    text = _in_units(campaign_text(), lambda h: ("dx [m]", 1e-3) if h == "dx" else (h, None))
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#")) + 1
    cells = lines[i].split(",")
    head = lines[i - 1].split(",")
    cells[head.index("dx [m]")] = "0.5"
    lines[i] = ",".join(cells)
    (tmp_path / "big.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"\(dx\): 0.5 m \(500 mm\) is outside the plausible range \[-100, 100\] mm"):
        read_stiffness_campaign(tmp_path / "big.csv", ROBOT)


def test_a_value_in_the_ranges_own_unit_is_printed_once(tmp_path):
    """dx [mm] of -224 is outside the range in the unit it is written in: '-224 mm', not the
    redundant '-224 mm (-224 mm)' (before)."""
    text = _in_units(campaign_text(), lambda h: ("dx [mm]", 1.0) if h == "dx" else (h, None))
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#")) + 1
    cells, head = lines[i].split(","), lines[i - 1].split(",")
    cells[head.index("dx [mm]")] = "-224"
    lines[i] = ",".join(cells)
    (tmp_path / "big.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as e:
        read_stiffness_campaign(tmp_path / "big.csv", ROBOT)
    assert "(dx): -224 mm is outside the plausible range [-100, 100] mm" in str(e.value), str(e.value)
    assert "(-224 mm)" not in str(e.value)


def test_the_fanuc_campaign_with_its_units_in_the_header(tmp_path):
    """The FANUC R-2000iC campaign (../shared/realdata) as its source gives
    it, rad and m, with the units written into the header: the same
    campaign as tests/realdata.py's conversion to deg and mm."""
    from realdata import FANUC, FANUC_ROBOT, fanuc_campaign_csv, missing, realdata_dir

    reason = missing(FANUC)
    if reason:
        print(f"skipped: {reason}")
        pytest.skip(reason)
    robot = load_robot(FANUC_ROBOT)
    converted = read_stiffness_campaign(fanuc_campaign_csv(tmp_path / "deg.csv"), robot)
    folder = realdata_dir() / FANUC
    cols = [np.loadtxt(folder / n, delimiter=",", skiprows=1) for n in ("joint_angles.csv", "forces.csv",
                                                                          "deltaX.csv")]
    head = ",".join([f"theta{i} [rad]" for i in range(1, 7)] + ["Fx [N]", "Fy [N]", "Fz [N]"]
                    + ["dx [m]", "dy [m]", "dz [m]"])
    rows = [",".join(repr(float(v)) for v in np.concatenate([c[i] for c in cols])) for i in range(len(cols[0]))]
    (tmp_path / "si.csv").write_text("# tool_mm: 6.9, 245.3, 319.3\n" + head + "\n" + "\n".join(rows) + "\n")
    si = read_stiffness_campaign(tmp_path / "si.csv", robot)
    np.testing.assert_allclose(si.q_deg, converted.q_deg, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(si.disp_mm, converted.disp_mm, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(si.force_N, converted.force_N, rtol=1e-9, atol=1e-7)


def test_a_clock_column_named_time_is_still_ignored(tmp_path):
    text = _in_units(campaign_text(), lambda h: (h, None))
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#"))
    lines = lines[:i] + [lines[i] + ",Time"] + [ln + ",10:32:15" for ln in lines[i + 1:]]
    (tmp_path / "clock.csv").write_text("\n".join(lines) + "\n")
    c = read_stiffness_campaign(tmp_path / "clock.csv", ROBOT)
    assert c.t_s is None and len(c) == 24
