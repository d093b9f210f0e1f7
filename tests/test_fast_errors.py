"""A mistyped file name or a bad argument is refused before Drake (or scipy)
is imported: the one-line error comes as fast as --help's answer.  Each
case runs in a fresh interpreter and asserts what was imported when the
error came (no timing: benchmarks/bench_bad_input.py times them against
--help)."""

import json
import subprocess
import sys

import pytest

PROBE = """
import json, sys
from robstiff_drake.commands.main import main
code = main(json.loads(sys.argv[1]))
print(json.dumps({"code": code, "heavy": sorted(m for m in ("pydrake", "scipy") if m in sys.modules)}))
"""

CASES = [  # (argv, a part of the error line, modules that must not be imported)
    (["simulate", "no_such_scenario"], "no such scenario file, and no packaged scenario", ("pydrake", "scipy")),
    (["simulate", "block_milling", "--replay", "r.png", "--out", "o"], "give a name ending in .html", ("pydrake",)),
    (["simulate", "block_milling", "--compensator", "missing.yaml"], "missing.yaml: no such run file",
     ("pydrake", "scipy")),
    (["simulate", "block_milling", "--robot", "no_such_robot"], "not a library robot", ("pydrake", "scipy")),
    (["sweep", "block_milling", "--period-ms", "4,x"], "'x' is not a number", ("pydrake",)),
    (["sweep", "block_milling", "--period-ms", "4", "--mode", "clever"], "expected plain and/or predictive",
     ("pydrake",)),
    (["sim-cell", "no_such_scenario", "--egm-to", "127.0.0.1:6510", "--netft-port", "49152"],
     "no such scenario file", ("pydrake", "scipy")),
    (["compensate", "--egm-port", "6510", "--netft", "127.0.0.1", "--model", "missing.json", "--payload", "p.yaml"],
     "--model missing.json: cannot read", ("pydrake", "scipy")),
    (["compensate", "--egm-port", "6510", "--netft", "127.0.0.1", "--model", "a_file.txt", "--payload", "a_file.txt",
      "--log", "."], "--log .: the folder holds an input of the command", ("pydrake", "scipy")),
    (["compensate", "--egm-port", "6510", "--netft", "127.0.0.1", "--model", "a_file.txt", "--payload", "a_file.txt",
      "--cutoff-hz", "600"], "--cutoff-hz: cutoff 600 Hz must be between 0 and the Nyquist rate 500 Hz",
     ("pydrake", "scipy")),
    (["compensate", "--egm-port", "6510", "--netft", "127.0.0.1", "--model", "a_file.txt", "--payload", "a_file.txt",
      "--servo", "12,17,60,0.9,7.5,3"], "--servo: expected 4 or 5 comma-separated numbers", ("pydrake", "scipy")),
    (["demo", "--robot", "no_such_robot"], "not a library robot", ("pydrake", "scipy")),
    (["demo", "--out", "a_file.txt"], "is a file, not a folder", ("pydrake",)),
    (["diagnose-run", "no_such_run"], "no such run folder", ("pydrake", "scipy")),
    (["identify", "missing.csv"], "missing.csv: cannot read", ("pydrake", "scipy")),
    (["identify", "a_file.txt", "--tool", "1,2"], "--tool: expected 3 comma-separated numbers", ("pydrake", "scipy")),
    (["diagnose", "missing.csv"], "missing.csv: cannot read", ("pydrake", "scipy")),
    (["calibrate-payload", "missing.csv"], "missing.csv: cannot read", ("pydrake", "scipy")),
    (["stiffness", "0", "0", "0", "--robot", "my_robot.yaml"], "my_robot.yaml: no such robot file",
     ("pydrake", "scipy")),
    (["synth", "stiffness", "c.csv", "--effect", "no_such_effect"], "unknown effect", ("pydrake", "scipy")),
]


@pytest.mark.parametrize("argv, message, not_imported", CASES, ids=[" ".join(c[0][:2]) + f" #{i}"
                                                                      for i, c in enumerate(CASES)])
def test_bad_input_is_refused_before_the_heavy_imports(tmp_path, argv, message, not_imported):
    (tmp_path / "a_file.txt").write_text("not a folder, not a campaign\n")
    proc = subprocess.run([sys.executable, "-c", PROBE, json.dumps(argv)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    err = proc.stderr.strip().splitlines()
    assert result["code"] == 2 and len(err) == 1 and message in err[0], (proc.stderr, result)
    assert not set(not_imported) & set(result["heavy"]), f"imported {result['heavy']} before refusing {argv}"


def test_another_robots_compensator_is_refused_before_the_path_is_computed(tmp_path, capsys, monkeypatch):
    """simulate --compensator with a compensator made for another robot was
    refused only after the path's joint reference and the scenario's
    identified model were computed (50 s on a loaded machine): now before."""
    from robstiff_drake.commands.main import main
    from robstiff_drake.diagrams import milling_cell, user_model
    from robstiff_drake.identification.runs import files as rf

    def too_late(*args, **kwargs):
        raise AssertionError("the path was computed before the compensator's robot was checked")

    # every module that binds planned_path by name binds the real one before it is patched (one imported while
    # the patch stood would keep too_late after the test: the error budget of a later test in this process did)
    import importlib
    import pkgutil

    import robstiff_drake.diagrams as diagrams_pkg

    for m in pkgutil.iter_modules(diagrams_pkg.__path__, "robstiff_drake.diagrams."):
        importlib.import_module(m.name)
    monkeypatch.setattr(milling_cell, "planned_path", too_late)
    monkeypatch.setattr(user_model, "resolve", too_late)
    payload = {"mass_kg": 40.0, "com_mm": [0.0, 0.0, 180.0], "force_bias_N": [0.0] * 3, "torque_bias_Nm": [0.0] * 3,
               "sensor_mount_rpy_deg": [0.0] * 3}
    settings = rf.CompensatorSettings(joint_stiffness_Nm_per_rad=[1e6] * 6, payload=payload,
                                      tool_point_mm=[0.0, 0.0, 350.0], cutter_diameter_mm=75.0, filter_cutoff_hz=2.0,
                                      robot="kr240_r2900")
    other = tmp_path / "compensator.yaml"
    other.write_text(rf.settings_text(settings, "x"), encoding="utf-8")
    code = main(["simulate", "short_block", "--compensator", str(other), "--out", str(tmp_path / "never")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "compensator.robot is kr240_r2900" in err and "not the simulated robot irb6400" in err, err
    assert not (tmp_path / "never").exists()
