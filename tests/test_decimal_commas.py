"""A campaign exported by a European-locale tool (Excel, a CMM's software):
';'-separated with decimal commas ('12,345;-0,5').  Read, as pandas reads
it with decimal=",", when the separator is ';' (or tab) and every number
writes its decimals with a comma, and said in a note; refused in one line
naming file, line, column and what to do where it is ambiguous: a
','-separated file with decimal commas, a '.' among decimal commas (a
thousands separator, or numbers written both ways).  Before: every decimal
comma was refused ("'20,2548' has a decimal comma; write the decimal point
as '.'"), the file from the user's own tool unread."""

import json
from pathlib import Path

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness.campaign import read_payload_campaign, read_stiffness_campaign
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "examples" / "campaign.csv"
PAYLOAD = ROOT / "examples" / "payload.csv"


def european(path, out, sep=";"):
    """``path`` as a decimal-comma locale saves it: ``sep`` between cells, ',' for the point."""
    lines = Path(path).read_text().splitlines()
    out.write_text("\n".join(ln if ln.startswith("#") else ln.replace(",", sep).replace(".", ",")
                             for ln in lines) + "\n")
    return out


def first_data_line(path):
    lines = Path(path).read_text().splitlines()
    return next(i for i, ln in enumerate(lines, 1) if not ln.startswith("#")) + 1


def edit_cell(path, out, line, column, value, sep=";"):
    lines = Path(path).read_text().splitlines()
    cells = lines[line - 1].split(sep)
    cells[column - 1] = value
    lines[line - 1] = sep.join(cells)
    out.write_text("\n".join(lines) + "\n")
    return out


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("sep", [";", "\t"])
def test_a_decimal_comma_campaign_is_the_same_campaign(tmp_path, sep):
    robot = load_robot()
    euro = european(CAMPAIGN, tmp_path / "euro.csv", sep)
    a, b = read_stiffness_campaign(CAMPAIGN, robot), read_stiffness_campaign(euro, robot)
    assert (a.q_deg == b.q_deg).all() and (a.force_N == b.force_N).all() and (a.disp_mm == b.disp_mm).all()
    p, q = read_payload_campaign(PAYLOAD, robot), read_payload_campaign(european(PAYLOAD, tmp_path / "p.csv"), robot)
    assert (p.q_deg == q.q_deg).all() and (p.force_N == q.force_N).all() and (p.torque_Nm == q.torque_Nm).all()


def test_identify_and_calibrate_payload_read_it_and_say_so(capsys, tmp_path):
    euro = european(CAMPAIGN, tmp_path / "euro.csv")
    assert cli(capsys, "identify", CAMPAIGN, "--json", tmp_path / "a.json")[0] == 0
    code, out, err = cli(capsys, "identify", euro, "--json", tmp_path / "b.json")
    assert code == 0, err
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert a["joint_stiffness_Nm_per_rad"] == b["joint_stiffness_Nm_per_rad"]
    notes = [ln for ln in err.splitlines() if "decimal commas" in ln]
    assert len(notes) == 1 and notes[0].startswith("robstiff: note: ") and "euro.csv" in notes[0], err
    assert "semicolon-separated" in notes[0] and "warning" not in notes[0]
    # in the JSON too (its 'notes', not 'warnings'; before: printed only)
    said = notes[0].removeprefix("robstiff: note: ")
    assert b["notes"] == [said] and said not in b["warnings"] and "notes" not in a
    # and not said of a file with decimal points
    assert "decimal commas" not in cli(capsys, "identify", CAMPAIGN)[2]
    code, out, err = cli(capsys, "calibrate-payload", european(PAYLOAD, tmp_path / "payload.csv"))
    assert code == 0 and "mass                39.98" in out and "payload.csv: read with decimal commas" in err, err


def test_a_comma_separated_file_with_decimal_commas_is_refused(capsys, tmp_path):
    bad = european(CAMPAIGN, tmp_path / "comma.csv", sep=",")
    code, out, err = cli(capsys, "identify", bad)
    line = first_data_line(bad)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert f"comma.csv:{line}: expected 14 cells" in err and "from column 2 (seq)" in err, err
    assert "';'-separated" in err and "'.' decimals" in err, err
    # quoted cells (csv's QUOTE_ALL): the cell named by its column
    euro = european(CAMPAIGN, tmp_path / "euro.csv").read_text().splitlines()
    quoted = tmp_path / "quoted.csv"
    quoted.write_text("\n".join(ln if ln.startswith("#") else ",".join(f'"{c}"' for c in ln.split(";"))
                                for ln in euro) + "\n")
    code, _, err = cli(capsys, "identify", quoted)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"quoted.csv:{line}, column 3 (q1): '20,2548' has a decimal comma in a ','-separated file" in err, err
    assert "';'-separated" in err, err


@pytest.mark.parametrize("value, what", [("1.234,5", "thousands"), ("136.940047", "point")])
def test_a_point_among_decimal_commas_is_refused(capsys, tmp_path, value, what):
    euro = european(CAMPAIGN, tmp_path / "euro.csv")
    line = first_data_line(euro) + 2
    bad = edit_cell(euro, tmp_path / f"{what}.csv", line, 9, value)
    code, out, err = cli(capsys, "identify", bad)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert f"{what}.csv:{line}, column 9 (fx): '{value}' has a '.' in a file of decimal commas" in err, err
    assert "thousands separator" in err and f"line {line - 2}:" in err, err
