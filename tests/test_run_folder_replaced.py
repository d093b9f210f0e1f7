"""A run folder written over an earlier one says so (on stderr, with the
earlier run's id): a user who ran `simulate JOB --out run` twice lost the
first result with no word (cli.md: an earlier run folder is replaced)."""

from robstiff_drake.io import RUN_ID_FILE, RunFolder


def test_a_replaced_run_folder_is_said_with_its_run_id(tmp_path, capsys):
    out = tmp_path / "run"
    with RunFolder(out) as run:
        run.write("a.txt", "first")
    first = (out / RUN_ID_FILE).read_text().strip()
    assert capsys.readouterr().err == ""  # a new folder: nothing to say
    with RunFolder(out) as run:
        run.write("a.txt", "second")
    captured = capsys.readouterr()
    assert captured.out == ""  # (stdout may be --json -)
    lines = [ln for ln in captured.err.splitlines() if "replaced" in ln]
    assert len(lines) == 1 and str(out) in lines[0] and first in lines[0], captured.err
    assert (out / "a.txt").read_text() == "second"
