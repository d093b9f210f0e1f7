"""compensate-program's line about the compensator's identified model names
where each part comes from: a scenario with model.identified_json (a user's
`identify --json`) was said to use "a simulated stiffness campaign"."""

from pathlib import Path

from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_models import identified_parts

ROOT = Path(__file__).resolve().parents[1]


def test_the_identified_models_parts_name_the_users_files(tmp_path):
    (tmp_path / "k.json").write_text('{"joint_stiffness_Nm_per_rad": [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5]}')
    text = (ROOT / "tests" / "data" / "short_block.yaml").read_text()
    job = tmp_path / "job.yaml"
    assert text.rstrip().endswith("  source: nominal")  # (the file's last key)
    job.write_text(text.rstrip().removesuffix("source: nominal") + "source: identified\n  identified_json: k.json\n")
    sc = load_scenario(str(job))
    said = identified_parts(sc)
    assert "k.json (model.identified_json)" in said and "simulated stiffness campaign" not in said
    assert "simulated payload calibration" in said


def test_without_the_users_files_the_parts_are_simulated():
    sc = load_scenario(str(ROOT / "tests" / "data" / "short_block.yaml"))
    assert identified_parts(sc).startswith("a simulated stiffness campaign, a simulated payload calibration")
