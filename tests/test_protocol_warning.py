"""compensate and sim-cell default to ABB's EGM: a newcomer's FANUC (or
KUKA) robot file with the default protocol waited for EGM messages its
controller never sends, without a word.  The robot file's manufacturer
now names the protocol its controller speaks, as a warning."""

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.commands.options import protocol_warning
from robstiff_drake.model.robot import load_robot


@pytest.mark.parametrize("name, right", [("irb6400", "egm"), ("kr240_r2900", "rsi"), ("r2000ic_165f", "stream-motion")])
def test_each_maker_has_its_protocol(name, right):
    robot = load_robot(name)
    assert protocol_warning(robot, right) is None
    for other in {"egm", "rsi", "stream-motion"} - {right}:
        line = protocol_warning(robot, other)
        assert line is not None and f"--controller-protocol {right}" in line and f"is {other}" in line


def test_compensate_warns_before_it_reads_the_model(tmp_path, capsys):
    (tmp_path / "k.json").write_text("{}")
    (tmp_path / "p.yaml").write_text("payload_calibration: {}\n")
    code = main(["compensate", "--robot", "r2000ic_165f", "--listen-port", "6510", "--netft", "127.0.0.1",
                 "--model", str(tmp_path / "k.json"), "--payload", str(tmp_path / "p.yaml")])
    err = capsys.readouterr().err
    assert code == 2
    assert ("robstiff: warning: r2000ic_165f is a FANUC arm" in err
            and "FANUC's Stream Motion, --controller-protocol stream-motion" in err), err
    code = main(["compensate", "--robot", "r2000ic_165f", "--controller-protocol", "stream-motion", "--listen-port",
                 "0", "--netft", "127.0.0.1", "--model", str(tmp_path / "k.json"), "--payload", str(tmp_path / "p.yaml")])
    assert code == 2 and "FANUC arm" not in capsys.readouterr().err


def test_compensate_carries_the_warning_into_summary_json(tmp_path):
    """A KUKA arm streamed over EGM (legal: the conventions' tests do it on purpose): the run goes on and its
    summary.json's warnings carry the protocol line the text printed (the standards: in the text and the JSON)."""
    import json
    import os
    import sys

    import numpy as np

    sys.path.insert(0, os.path.dirname(__file__))
    import cell_helpers as h

    robot = load_robot("kr240_r2900")
    model, payload, _, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=0.5)
    q0 = np.degrees(ref_fn(0.0))
    sensor = h.FakeSensor(h.hold_wrench(robot, ref_fn(0.0)))
    log = str(tmp_path / "log")
    proc, code, err = h.held_run(model, payload, sensor, h.free_udp_port(), q0, 20, log=log,
                                 extra=["--robot", "kr240_r2900"])
    assert code == 0, err
    said = [x for x in (proc.early_err + err).splitlines() if "is a KUKA arm" in x]
    assert said and said[0].startswith("robstiff: warning: ") and "--controller-protocol rsi" in said[0], said
    summary = json.loads(open(os.path.join(log, "summary.json")).read())
    warned = [w for w in summary["warnings"] if "is a KUKA arm" in w]
    assert len(warned) == 1 and warned[0] in said[0], summary["warnings"]
