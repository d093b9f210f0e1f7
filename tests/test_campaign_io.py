"""Measurement files: format and every bad-input case, through the CLI
(one line on stderr naming file/line/column, exit status 2, no output file)."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.model.robot import load_robot

ROBOT = load_robot()


def campaign_text(n=24, seed=0, **kw):
    c = synth.stiffness_campaign(ROBOT, n=n, seed=seed, **kw)
    return synth.stiffness_csv(c, robot=ROBOT, noise_mm=0.01, seed=seed, force_N=300.0, tool_m=np.zeros(3),
                               how="test")


def edit(text, fn):
    """Apply fn(header, rows) to the non-comment lines of a CSV text."""
    lines = text.splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    body = [ln.split(",") for ln in lines if not ln.startswith("#")]
    header, rows = fn(body[0], body[1:])
    return "\n".join(comments + [",".join(header)] + [",".join(r) for r in rows]) + "\n"


def identify_cli(capsys, tmp_path, text, *extra):
    data = tmp_path / "data.csv"
    data.write_text(text)
    out = tmp_path / "out.json"
    code = main(["identify", str(data), "--json", str(out), *extra])
    _, err = capsys.readouterr()
    return code, err.strip(), out, data


def test_good_file_with_reordered_and_extra_columns(capsys, tmp_path):
    def shuffle(h, rows):
        order = list(reversed(range(len(h))))
        return [h[i] for i in order] + ["operator"], [[r[i] for i in order] + ["anna"] for r in rows]

    code, err, out, _ = identify_cli(capsys, tmp_path, edit(campaign_text(), shuffle))
    assert code == 0, err
    res = json.loads(out.read_text())
    assert res["n_measurements"] == 24
    for key in ("joint_stiffness_Nm_per_rad", "joint_stiffness_std_Nm_per_rad", "identifiable", "rms_residual_mm",
                "n_measurements", "condition_number"):
        assert key in res
    assert len(res["residuals"]) == 24 and res["residuals"][0]["line"] == 10  # 8 comment lines + header


def _drop_column(name):
    def fn(h, rows):
        i = h.index(name)
        return h[:i] + h[i + 1:], [r[:i] + r[i + 1:] for r in rows]
    return fn


def _rename_column(old, new):
    def fn(h, rows):
        return [new if x == old else x for x in h], rows
    return fn


def _set_cell(row, name, value):
    def fn(h, rows):
        rows[row][h.index(name)] = value
        return h, rows
    return fn


def _scale(cols, factor):
    def fn(h, rows):
        for r in rows:
            for c in cols:
                r[h.index(c)] = repr(float(r[h.index(c)]) * factor)
        return h, rows
    return fn


BAD = [
    ("missing column", _drop_column("dz"), "data.csv:9: missing column 'dz'"),
    ("misspelled column", _rename_column("fz", "fzz"), "missing column 'fz' (is 'fzz' a misspelling?)"),
    ("non-numeric cell", _set_cell(3, "fy", "abc"), "data.csv:13, column 10 (fy): 'abc' is not a number"),
    ("nan", _set_cell(0, "dx", "nan"), "data.csv:10, column 12 (dx): 'nan' is not a finite number"),
    ("inf", _set_cell(5, "q2", "inf"), "data.csv:15, column 4 (q2): 'inf' is not a finite number"),
    ("empty cell", _set_cell(2, "q5", ""), "data.csv:12, column 7 (q5): empty cell"),
    ("duplicated header", _rename_column("seq", "fx"), "data.csv:9: duplicated column 'fx' (columns 2 and 9)"),
    ("fewer rows than unknowns", lambda h, r: (h, r[:5]), "5 measurement rows, fewer than the 6 unknowns"),
    ("all-zero forces", _scale(["fx", "fy", "fz"], 0.0), "all forces are zero"),
    ("metres", _scale(["dx", "dy", "dz"], 1e-3), "look like metres, not mm"),
    ("micrometres", _scale(["dx", "dy", "dz"], 1e3), "outside the plausible range [-100, 100] mm (other units?)"),
    ("micrometres, small", _scale(["dx", "dy", "dz"], 1e2 / 1.5), "look like micrometres, not mm"),
    ("joint limit", _set_cell(1, "q2", "85"), "data.csv:11, column 4 (q2): 85 deg is outside the joint limit [-70, 70] deg"),
    ("short row", lambda h, r: (h, [r[0][:-1]] + r[1:]), "data.csv:10: expected 14 cells (as in the header), got 13"),
]


@pytest.mark.parametrize("name, fn, message", BAD, ids=[b[0] for b in BAD])
def test_bad_stiffness_file(capsys, tmp_path, name, fn, message):
    code, err, out, _ = identify_cli(capsys, tmp_path, edit(campaign_text(), fn))
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert message in err
    assert "Traceback" not in err
    assert not out.exists()  # nothing half-written
    assert [p.name for p in tmp_path.iterdir()] == ["data.csv"]


def test_empty_file_and_header_only(capsys, tmp_path):
    code, err, *_ = identify_cli(capsys, tmp_path, "# only a comment\n\n")
    assert code == 2 and "empty file" in err
    code, err, *_ = identify_cli(capsys, tmp_path, "q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz\n")
    assert code == 2 and "no data rows after the header (line 1)" in err


def test_missing_file(capsys, tmp_path):
    code = main(["identify", str(tmp_path / "nope.csv")])
    _, err = capsys.readouterr()
    assert code == 2 and "nope.csv: cannot read" in err


def test_bad_payload_file(capsys, tmp_path):
    c = synth.payload_campaign(ROBOT, n=15, seed=0)
    text = synth.payload_csv(c, noise_N=1.0, noise_Nm=0.1, seed=0, how="test")
    bad = text.replace("q1,q2,q3,q4,q5,q6,fx,fy,fz,mx,my,mz", "q1,q2,q3,q4,q5,q6,fx,fy,fz,mx,my,mzz")
    path = tmp_path / "p.csv"
    path.write_text(bad)
    code = main(["calibrate-payload", str(path), "--json", str(tmp_path / "o.json")])
    _, err = capsys.readouterr()
    assert code == 2 and "missing column 'mz' (is 'mzz' a misspelling?)" in err
    assert not (tmp_path / "o.json").exists()
