"""Benchmark: what the block pass's remaining pydrake crossings cost, in
machine instructions per call (valgrind's callgrind), by themselves:

* the wrist sensor's read of the plant's reaction forces: pydrake converts
  the port's whole ``std::vector<SpatialForce>`` (nine joints on the
  library's arm) to a Python list, and the sensor keeps one element's
  coefficients (systems/wrist_sensor.WristForceSensor.true_wrench);
* the milling force's applied load: a new ``SpatialForce`` from its
  6-vector, set on the reused ``ExternallyAppliedSpatialForce``
  (systems/milling_force.MillingForceSource._update).

Each case runs ``N`` identical calls inside ``sorted(..., key=...)``, and
callgrind collects only inside the sort (``--toggle-collect``), so nothing
of Python's start or pydrake's import is counted; the empty key's count is
subtracted.  The figure does not depend on the machine's load.  Needs
valgrind (``VALGRIND``, default /usr/bin/valgrind) and callgrind_annotate;
a few minutes.  No target: figures only (docs/results.md, 5. Speed).
Run: python3 benchmarks/pydrake_crossings.py
"""

import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

N = 1000
VALGRIND = os.environ.get("VALGRIND", "/usr/bin/valgrind")

_SCRIPT = """
import sys
import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
sf = np.arange(6.0)
reactions = AbstractValue.Make([SpatialForce(sf)] * 9)  # (the plant's port's value type, nine joints)
applied = ExternallyAppliedSpatialForce()
cases = {  # (each key is the loop's index, so the sort compares ints)
    "empty": lambda i: (None, i)[1],
    "reactions": lambda i: (reactions.get_value(), i)[1],
    "sensor_read": lambda i: (reactions.get_value()[7].get_coeffs().tolist(), i)[1],
    "spatial_force": lambda i: (SpatialForce(sf), i)[1],
    "spatial_force_set": lambda i: (setattr(applied, "F_Bq_W", SpatialForce(sf)), i)[1],
}
sorted(range(int(sys.argv[2])), key=cases[sys.argv[1]])
"""

CASES = (
    ("reactions", "read of the nine joints' reaction forces (the list)"),
    ("sensor_read", "the same and one joint's coefficients (the sensor)"),
    ("spatial_force", "SpatialForce from a 6-vector (the milling force)"),
    ("spatial_force_set", "the same, set on ExternallyAppliedSpatialForce"),
)


def count(folder, case):
    """Instructions inside the sort of ``N`` calls of ``case``."""
    out = os.path.join(folder, f"{case}.callgrind")
    subprocess.run([VALGRIND, "--tool=callgrind", f"--callgrind-out-file={out}", "--toggle-collect=*list_sort_impl*",
                    sys.executable, os.path.join(folder, "crossing.py"), case, str(N)],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    text = subprocess.run(["callgrind_annotate", out], check=True, capture_output=True, text=True).stdout
    return int(re.search(r"([\d,]+)\s+\(100\.0%\)\s+PROGRAM TOTALS", text).group(1).replace(",", ""))


def main():
    if not (os.path.exists(VALGRIND) and shutil.which("callgrind_annotate")):
        print(f"no valgrind at {VALGRIND} or no callgrind_annotate (install valgrind, or set VALGRIND): "
              f"nothing measured")
        return 0
    with tempfile.TemporaryDirectory() as folder, ThreadPoolExecutor(2) as pool:
        with open(os.path.join(folder, "crossing.py"), "w") as f:
            f.write(_SCRIPT)
        runs = {case: pool.submit(count, folder, case) for case in ("empty",) + tuple(c for c, _ in CASES)}
        totals = {case: run.result() for case, run in runs.items()}
    print(f"instructions per call (thousands; callgrind, {N} calls each, the empty loop's subtracted):")
    for case, label in CASES:
        print(f"  {label:58s} {(totals[case] - totals['empty']) / N / 1e3:6.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
