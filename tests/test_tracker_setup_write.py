"""`diagnose --write-robot` carries the setup findings (identification/
tracker/setup_terms.py, robot_writer.setup_corrections): a payload declared
wrong (mass, centre of mass) is written as the diagnosis found it, read back,
and the same campaign diagnosed with the written file no longer names it,
its held-out error no worse; a vertical turned (no robot file key holds it)
is said in the file's header, not written; the input is never touched."""

import json

import numpy as np
import pytest
import tracker_world as tw

from robstiff_drake.commands.main import main
from robstiff_drake.model.robot import load_robot

NOISE = 0.03


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    robot = load_robot("irb6400")  # the arm carries the file's 40 kg at (0, 0, 180) mm
    path = tmp_path_factory.mktemp("write") / "irb6400.csv"
    path.write_text(tw.make_tracker_campaign(robot, 21, n=600, noise_mm=NOISE).csv_text)
    return robot, path


def _diagnose(capsys, data, robot, *more):
    code = main(["diagnose", str(data), "--robot", str(robot), "--noise-mm", str(NOISE), "--json", "-",
                 *map(str, more)])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def _planted(robot, tmp_path, flow):
    """The library's robot file with the payload declared 20 kg at 80 mm (the arm's is 40 kg at 180 mm), the
    payload section in block style or as a one-line flow mapping (the writer then re-emits the document)."""
    text = open(robot.source).read()
    block = "payload:\n  mass_kg: 40.0\n  com_mm: [0.0, 0.0, 180.0]\n  tool_point_mm: [0.0, 0.0, 350.0]\n"
    assert block in text
    new = ("payload: {mass_kg: 20.0, com_mm: [0.0, 0.0, 80.0], tool_point_mm: [0.0, 0.0, 350.0]}\n" if flow else
           block.replace("40.0", "20.0").replace("180.0", "80.0"))
    path = tmp_path / "planted.yaml"
    path.write_text(text.replace(block, new))
    return path


@pytest.mark.parametrize("flow", [False, True])
def test_a_wrong_payload_is_written_as_found_and_not_named_again(capsys, campaign, tmp_path, flow):
    robot, data = campaign
    planted = _planted(robot, tmp_path, flow)
    before = planted.read_bytes()
    out = tmp_path / "corrected.yaml"
    rep = _diagnose(capsys, data, planted, "--write-robot", out)
    found = {f["name"] for f in rep["setup_findings"]}
    assert {"payload_mass", "payload_com"} <= found, rep["setup_findings"]
    assert planted.read_bytes() == before  # the input untouched
    new = load_robot(str(out))
    assert new.payload.mass_kg == pytest.approx(40.0, abs=2.0)
    np.testing.assert_allclose(new.payload.com_m * 1e3, [0.0, 0.0, 180.0], atol=15.0)
    text = out.read_text()
    assert "payload.mass_kg (a setup finding)" in text and "# payload.com_mm: [" in text
    assert rep["corrected_robot"]["fk_check_mm"] < 1e-6
    again = _diagnose(capsys, data, out)
    assert not again["setup_findings"], again["setup_findings"]
    assert not {"payload_mass", "payload_com"} & set(again["selected_effects"])
    assert again["rms_after_mm"] <= 1.01 * rep["rms_after_mm"], (rep["rms_after_mm"], again["rms_after_mm"])


def test_a_turned_vertical_is_said_in_the_header_not_written(capsys, campaign, tmp_path):
    robot, data = campaign
    lines = data.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    cols = lines[head].split(",")
    ix, iy, iz = (cols.index(c) for c in ("x", "y", "z"))
    a = np.deg2rad(1.0)  # the instrument's frame turned by 1 deg about its x axis
    rows = []
    for line in lines[head + 1:]:
        v = line.split(",")
        y, z = float(v[iy]), float(v[iz])
        v[iy], v[iz] = f"{np.cos(a) * y - np.sin(a) * z:.5f}", f"{np.sin(a) * y + np.cos(a) * z:.5f}"
        rows.append(",".join(v))
    turned = tmp_path / "turned.csv"
    turned.write_text("\n".join(lines[:head + 1] + rows) + "\n")
    out = tmp_path / "corrected.yaml"
    rep = _diagnose(capsys, turned, robot.source, "--write-robot", out)
    assert "gravity_tilt" in {f["name"] for f in rep["setup_findings"]}, rep["setup_findings"]
    text = out.read_text()
    header = text[:text.index("\nname:")]
    assert "NOT WRITTEN (no robot file key holds it)" in header and "level the tracker" in header
    assert load_robot(str(out)).payload.mass_kg == 40.0  # nothing else changed for it
