"""The README's test command (the line .ci/run executes): every part of
the suite runs whatever an earlier part gave, and the command fails when
any part failed.  Run as .ci/run runs it (bash, ``set -euo pipefail``,
``eval``) with ``python3`` a shell function that records each call and
fails the parts a case says, so no test runs inside this one."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_command():
    """The line .ci/run takes: the first starting with ``python3 `` after the marker."""
    lines = (ROOT / "README.md").read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if "ci:test-command" in ln)
    return next(ln for ln in lines[start + 1:] if ln.startswith("python3 "))


@pytest.mark.parametrize("fail_rt, fail_rest", [(0, 0), (1, 0), (0, 1), (1, 1)],
                         ids=["all-pass", "realtime-fails", "rest-fails", "both-fail"])
def test_every_part_runs_and_a_failed_part_fails_the_command(tmp_path, fail_rt, fail_rest):
    (tmp_path / ".venv" / "bin").mkdir(parents=True)
    (tmp_path / ".venv" / "bin" / "activate").write_text("")
    calls = tmp_path / "calls.txt"
    script = f"""set -euo pipefail
python3() {{
    echo "$*" >> {calls}
    case "$*" in
        *pytest*"not realtime"*) return {fail_rest};;
        *pytest*realtime*) return {fail_rt};;
    esac
    return 0
}}
eval "$CMD"
"""
    cp = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                        env={"PATH": os.environ["PATH"], "CMD": readme_command()})
    pytest_runs = [c for c in calls.read_text().splitlines() if "pytest" in c]
    assert len(pytest_runs) == 2 and "not realtime" in pytest_runs[1], pytest_runs  # the rest ran whatever
    assert (cp.returncode != 0) == bool(fail_rt or fail_rest), (cp.returncode, cp.stdout, cp.stderr)
