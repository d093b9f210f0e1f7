"""A size beyond the typical is a prior, not a veto: on campaigns made by
Drake with a setup mistake (tests/setup_errors.py: a tool point 250 mm off,
an untared force sensor, a soft forearm, millimetres read as metres) the
diagnosis keeps the term that names it, says what it implies and the check
to make, and reaches the noise; a sign physics forbids stays refused; with
no noise floor nothing beyond the typical is kept."""

import json
from dataclasses import replace

import numpy as np
import open_world as ow
import pytest
import setup_errors as se

from robstiff_drake.commands.diagnose import to_dict
from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.io import Warnings, emit_json

NOISE = se.NOISE_MM
SEED = 11


@pytest.fixture(scope="module")
def made():
    return {}


def _diagnosed(robot, made, kind):
    if kind not in made:
        c = se.make_campaign(kind, SEED)
        w = Warnings(quiet=True)
        made[kind] = (c, diagnose(robot, c.campaign, tool_m=c.declared_tool_m, noise_mm=NOISE, warnings=w), w)
    return made[kind]


def _only_term(d, name):
    assert [t["name"] for t in d.terms] == [name], d.terms
    t = d.terms[0]
    assert t["beyond_typical"] is True and t["plausible"] is False and t["prior_size"]
    return t


@pytest.mark.parametrize("kind", ["tool_point", "untared", "soft_forearm"])
def test_a_setup_mistake_is_named_and_reaches_the_noise(robot, made, kind):
    c, d, w = _diagnosed(robot, made, kind)
    t = _only_term(d, se.EXPECTED[kind])
    assert d.rms_before_mm > 1.5 * NOISE and d.rms_after_mm <= 1.25 * NOISE, (d.rms_before_mm, d.rms_after_mm)
    assert d.explains_data is True and "setup finding" in d.verdict and t["finding"] in d.verdict
    assert any(t["name"] in m and "decisive" in m for m in w)
    values = np.array(list(t["params"].values()))
    if kind == "tool_point":  # (d_x, d_y, d_z) mm in the flange frame
        assert np.allclose(values, se.TOOL_SHIFT_M * 1e3, atol=8.0), values
        assert "mm beyond the declared tool point" in t["finding"] and "`# tool_mm:`" in t["finding"]
    elif kind == "untared":  # the term's b is what the reading lacks: minus the bias
        assert np.allclose(-values, se.BIAS_N, atol=2.0), values
        assert "27 N with no load" in t["finding"] and "tare the sensor" in t["finding"]
    else:
        assert abs(values[0] - se.FOREARM_M_PER_N * 1e6) < 0.06, values
        assert "soft forearm or a loose joint" in t["finding"]


def test_without_a_mistake_nothing_is_added(robot, made):
    _, d, _ = _diagnosed(robot, made, "none")
    assert d.terms == [] and d.explains_data is True and d.alternatives == []
    assert d.rms_after_mm <= 1.25 * NOISE


def test_the_json_carries_the_prior_and_the_finding(robot, made, tmp_path):
    c, d, _ = _diagnosed(robot, made, "tool_point")
    emit_json(to_dict(d, c.campaign), tmp_path / "d.json")
    res = json.loads((tmp_path / "d.json").read_text())
    (t,) = res["terms"]
    assert t["prior_size"].startswith("<= 20 mm") and t["beyond_typical"] is True and "tool_mm" in t["finding"]
    assert res["alternatives"] == []


def test_millimetres_read_as_metres_are_refused_with_the_check(capsys, robot, tmp_path):
    # beyond the reader's +-100 mm: the cell is named; within it (a smaller load), the model's check names the scale
    c = se.make_campaign("mm_as_m", SEED)
    data = tmp_path / "mm_as_m.csv"
    data.write_text(ow.to_csv(c))
    code = main(["diagnose", str(data), "--noise-mm", "0.01"])
    _, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in err
    assert "millimetres read as metres" in err and "(dx)" in err
    # loads of 15 N: the displacements within the reader's range, still 1000x what the model predicts
    small = replace(c.campaign, force_N=c.campaign.force_N * 0.05, disp_mm=c.campaign.disp_mm * 0.05)
    with pytest.raises(InputError, match=r"look like millimetres read as metres \(or micrometres\), not mm, or fx,fy,fz "
                                         r"are .*x too small .*\(the readings are [\d.e+]+x that\); check the units of "
                                         r"dx,dy,dz .* and of fx,fy,fz"):
        identify(robot, small, tool_m=c.declared_tool_m)


def test_a_negative_compliance_stays_refused(robot):
    # the forearm "bends" against the force: a compliance physics forbids, whatever the evidence
    c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=12,
                                 effect_params={"link_compliance": {"c_link_m_per_N": -0.3e-6}})
    d = diagnose(robot, c.to_campaign(), noise_mm=NOISE)
    assert "link_compliance" not in [t["name"] for t in d.terms]
    lead = {r["name"]: r for r in d.leads}["link_compliance"]
    assert lead["forbidden"] is True and "non-physical" in lead["reason"]
    assert lead["rms_mm"] <= 1.25 * NOISE  # it fits; it is refused for its sign
    assert all(not a.get("terms") or "link_compliance" not in a["terms"] for a in d.alternatives)


def test_without_a_noise_floor_a_size_beyond_the_typical_is_not_kept(robot, made):
    c, _, _ = _diagnosed(robot, made, "tool_point")
    d = diagnose(robot, c.campaign, tool_m=c.declared_tool_m)
    assert "tool_offset" not in [t["name"] for t in d.terms]
    lead = {r["name"]: r for r in d.leads}["tool_offset"]
    assert "no noise floor" in lead["reason"] and lead["forbidden"] is False


def test_every_term_has_a_typical_range_and_a_finding():
    # a term the search may keep beyond its typical size says what that range is and what to check
    from robstiff_drake.identification.diagnosis.candidates import CANDIDATES
    from robstiff_drake.identification.diagnosis.dictionary import DICTIONARY
    from robstiff_drake.identification.diagnosis.findings import finding, prior_size

    for name, t in {**CANDIDATES, **DICTIONARY}.items():
        assert prior_size(name), name
        text = finding(name, np.full(len(t.params), 1e-3), {}, "beyond")
        assert ": " in text and not text.startswith("beyond its typical size"), (name, text)  # what, then the check


def test_an_untared_moment_is_named(robot):
    # a moment channel read with 20 N*m and no load (8x the typical 2.4 N*m): before, no term could carry it (the
    # six springs kept, nothing named); the moment columns' bias is a dictionary term tried only with mx,my,mz
    c = se.make_campaign("none", SEED)
    m = np.zeros_like(c.campaign.force_N)
    m[:, 0] = 20.0
    d = diagnose(robot, replace(c.campaign, moment_Nm=m, has_moments=True), tool_m=c.declared_tool_m, noise_mm=NOISE)
    kept = {t["name"]: t for t in d.terms}
    assert "moment_bias" in kept and kept["moment_bias"]["beyond_typical"], d.verdict
    assert "the moment reads 20" in kept["moment_bias"]["finding"] and "tare" in kept["moment_bias"]["finding"]
    assert d.rms_after_mm <= 1.25 * NOISE
    # no moment columns: the term is not tried
    d0 = diagnose(robot, c.campaign, tool_m=c.declared_tool_m, noise_mm=NOISE)
    assert all(r.name != "moment_bias" or r.status != "ok" for rnd in d0.rounds for r in rnd)
