"""The files of one machining run as a cell records them (docs/run_files.md):

  wrench_log.csv    the wrist sensor's raw readings, sensor frame, with times
  joint_log.csv     the controller's joint angles (motor side) and the
                    compensator's correction in them, once per controller period
  compensator.yaml  the compensator's settings (nothing of the plant)
  scan.csv          the laser or CMM scan of the machined face: positions,
                    nominal and measured heights, the instrument's noise
  RUN_ID            the run's id; every file above carries it in a
                    ``# run_id: ...`` line

A reader for each (an InputError of one line naming the file, line and
column of anything wrong) and a writer (text) for each, which
``robstiff simulate --out`` uses so that a simulated run folder holds the
same files: the logs and the scan in identification/runs/logs.py, the
settings in identification/runs/settings.py, the names and the tables'
text in identification/runs/tables.py; here the run folder as a whole.
Files whose names start with ``sim_`` are the simulation's truth (the
plant, the actual tool path); nothing here reads them.

Plain numpy and PyYAML; no Drake.  Units are in the column and key names;
angles at the interface are the controller's degrees.
"""

from dataclasses import dataclass
from pathlib import Path

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.runs.logs import JointLog, Scan, WrenchLog, read_joint_log, read_scan, read_wrench_log
from robstiff_drake.identification.runs.settings import CompensatorSettings, read_settings
# SERVO_KEYS, settings_text: cell/settings_file.py reads them here (it was being edited elsewhere when this file was
# split); move its import to run_settings and drop this line
from robstiff_drake.identification.runs.settings import SERVO_KEYS, settings_text  # noqa: F401
from robstiff_drake.identification.runs.tables import (CELL_FILES, JOINT_LOG, SCAN, SETTINGS, WRENCH_LOG, fail, read_text,
                                                      run_file)
from robstiff_drake.io import RUN_ID_FILE


@dataclass
class RunFiles:
    """A run folder's cell files (the ones a real cell has)."""

    folder: Path
    run_id: str
    settings: CompensatorSettings
    scan: Scan
    wrench: WrenchLog = None
    joints: JointLog = None


# ---------------------------------------------------------------- run folders


def read_run_id(folder):
    """The run id in ``folder``/RUN_ID (InputError if there is none)."""
    p = run_file(folder, RUN_ID_FILE)
    if not p.is_file():
        raise InputError(f"{folder}: no {RUN_ID_FILE} file (a run folder names its run there; every file of the "
                         "run carries the same id in a '# run_id: ...' line)")
    rid = read_text(p).strip()
    if not rid or len(rid.split()) != 1:
        fail(p, 1, what=f"expected one run id, got {excerpt(rid)}")
    return rid


def check_run_id(path, meta, run_id):
    """Refuse a file that does not carry the folder's run id."""
    if "run_id" not in meta:
        fail(path, what=f"no '# run_id: ...' line; every file of a run folder carries its run id ({run_id})")
    value, line = meta["run_id"]
    if value != run_id:
        fail(path, line, what=f"run_id {value} is not this folder's run ({run_id} in {RUN_ID_FILE}): the folder "
                              "mixes files of different runs")


READERS = {WRENCH_LOG: read_wrench_log, JOINT_LOG: read_joint_log, SETTINGS: read_settings, SCAN: read_scan}


def load_run_files(folder, names=CELL_FILES, scan=None):
    """Read the cell files ``names`` of a run folder (each must carry the
    folder's run id); RunFiles.  Never opens a ``sim_`` file.  ``scan``: a
    scan file made outside the run (a CMM's or a laser line's, no run id)
    read instead of the folder's scan.csv."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such run folder")
    if scan is not None:
        names = tuple(n for n in names if n != SCAN)
    for name in names:
        if not run_file(folder, name).is_file():
            raise InputError(f"{folder}: missing {name} (a run folder holds {', '.join(CELL_FILES)} and "
                             f"{RUN_ID_FILE}, see docs/run_files.md; `robstiff simulate` writes them for its "
                             "compensated cut)")
    run_id = read_run_id(folder)
    got = {}
    for name in names:
        meta, data = READERS[name](folder / name)
        check_run_id(folder / name, meta, run_id)
        got[name] = data
    if scan is not None:
        got[SCAN] = read_scan(scan)[1]
    return RunFiles(folder, run_id, got[SETTINGS], got[SCAN], got.get(WRENCH_LOG), got.get(JOINT_LOG))
