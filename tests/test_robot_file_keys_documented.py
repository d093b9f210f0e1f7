"""docs/your_robot.md's table of a robot file's keys names every key of
robot_file.KEYS (the table a user writes a file from, by hand, from a data
sheet): a user's KR 210 file written from the table had no
joint_limits.speed_deg_per_s / acceleration_deg_per_s2, which the table did
not name, and `compensate` refused it on the day of the cell."""

import re
from pathlib import Path

from robstiff_drake.model.robot_file import KEYS

ROOT = Path(__file__).resolve().parents[1]


def key_table():
    """{key named in a row's first cell: the row's second cell} of the key
    table in docs/your_robot.md (the rows whose first cell names keys in
    backticks)."""
    rows = {}
    for line in (ROOT / "docs" / "your_robot.md").read_text().splitlines():
        m = re.match(r"\| ((?:`[A-Za-z0-9_]+`(?:, )?)+)(?: \(optional\))? \| (.*) \|$", line)
        if m:
            for name in re.findall(r"`([A-Za-z0-9_]+)`", m.group(1)):
                rows[name] = m.group(2)
    return rows


def test_every_key_of_a_robot_file_is_in_the_docs_table():
    rows = key_table()
    missing = []
    for key in KEYS:
        parts = key.split(".")
        top = parts[0].removesuffix("[]")
        if top not in rows:
            missing.append(key)
        elif len(parts) == 2 and not parts[0].endswith("[]") and f"`{parts[1]}" not in rows[top]:
            missing.append(key)  # a key of a block (joint_limits.speed_deg_per_s): named in its block's row
    assert not missing, f"docs/your_robot.md's key table does not name: {missing}"


def test_compensate_names_only_the_axis_limit_that_is_missing(tmp_path):
    """A robot file with the data sheet's axis speeds but no accelerations:
    compensate's refusal names the acceleration key alone (it said both were
    missing) and what to write."""
    import pytest

    from robstiff_drake.commands.compensate_inputs import check_axis_limits
    from robstiff_drake.errors import InputError
    from robstiff_drake.model.robot import load_robot

    text = (ROOT / "models" / "kr240_r2900.yaml").read_text()
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("acceleration_deg_per_s2:")]
    assert len(lines) == len(text.splitlines()) - 1
    path = tmp_path / "my_robot.yaml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as e:
        check_axis_limits(load_robot(path))
    line = str(e.value)
    assert "my_robot.yaml" in line and "'joint_limits.acceleration_deg_per_s2'" in line
    assert "speed_deg_per_s" not in line.split(": missing")[0] and "\n" not in line
