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


def _job_with_users_stiffness(tmp_path, program=None):
    (tmp_path / "k.json").write_text('{"joint_stiffness_Nm_per_rad": [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5]}')
    text = (ROOT / "tests" / "data" / "short_block.yaml").read_text()
    job = tmp_path / "job.yaml"
    job.write_text(text.rstrip().removesuffix("source: nominal") + "source: identified\n  identified_json: k.json\n")
    return job


def test_the_model_origin_names_the_users_file_by_its_path(tmp_path):
    """compensate-program's header and its reference's mark said "identified
    model (seed 20)" when the stiffness was the user's k.json: now its path."""
    from robstiff_drake.diagrams.scenario_models import model_origin

    sc = load_scenario(str(_job_with_users_stiffness(tmp_path)))
    said = model_origin(sc)
    assert f"stiffness from {tmp_path / 'k.json'}" in said and "simulated campaign" not in said
    assert "payload from a simulated calibration" in said and f"seed {sc.model.identification.seed}" in said
    assert model_origin(load_scenario(str(ROOT / "tests" / "data" / "short_block.yaml"))) == "nominal model"


def test_compensate_programs_header_and_json_name_the_users_file(tmp_path):
    import json

    from test_compensate_program import SHORT

    from robstiff_drake.commands.main import main

    (tmp_path / "k.json").write_text('{"joint_stiffness_Nm_per_rad": [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5]}')
    (tmp_path / "short.nc").write_text(SHORT)
    text = (ROOT / "diagrams" / "face_and_contour.yaml").read_text().replace("program: face_and_contour.nc",
                                                                            "program: short.nc")
    assert text.count("  source: identified\n") == 1
    (tmp_path / "short.yaml").write_text(text.replace("  source: identified\n",
                                                      "  source: identified\n  identified_json: k.json\n"))
    out = tmp_path / "out"
    assert main(["compensate-program", str(tmp_path / "short.yaml"), "--out", str(out), "--json",
                 str(tmp_path / "s.json"), "--no-simulate", "--refine-rounds", "0"]) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert f"stiffness from {tmp_path / 'k.json'}" in summary["model"]
    program = Path(summary["program"]).read_text()
    header = next(line for line in program.splitlines() if "ROBSTIFF COMPENSATE-PROGRAM" in line)
    assert f"stiffness from {tmp_path / 'k.json'}" in header
    mark = Path(summary["joint_reference"]).read_text().splitlines()[0]
    assert f"stiffness from {tmp_path / 'k.json'}" in mark
