"""Issue 19's G-code cases, as the code reads them: each case is a short
contour program over a 120 x 80 mm plate (top at z = 703 mm, the program's
zero 3 mm below it), changed as the issue's fuzz changed it; for each, how
the program is read: refused (the one line), or the path it runs (its
lowest point, largest x, the feed and the duration) and the warnings.

    python studies/gcode_reading_cases.py

Run it on another checkout (PYTHONPATH=that checkout) to compare: on the
code before the controller-like reader, every case ran (the comment's
hidden Z-25. cut 25 mm deep, F47.244 G20 ran at 47 mm/min) and F1e9 blamed
the scenario's path.feed_mm_per_s.  A few seconds; writes only to a
temporary folder."""

import sys
import tempfile
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.scenario import load_scenario, planned_path
from robstiff_drake.errors import InputError

SCENARIO = """name: gcode_reading_case
cutter: {{diameter_mm: 75.0, n_teeth: 6, spindle_rpm: 3600.0}}
cutting: {{axial_scale: 0.33}}
workpiece:
  boxes_mm:
    - [1540.0, 1660.0, -40.0, 40.0, 703.0]
toolpath:
  program: {program}
  work_offset_mm: [1600.0, 0.0, 700.0]
"""
PROGRAM = "G21 G17 G90\nG0 X-140. Y-20. Z20.\nZ5.\nG1 Z0. F1200.\n{middle}\nG0 Z20.\nM30\n"
CASES = {
    "VT inside a comment hides Z-25.": "N70 X40. ; (was Z-0.3)\x0bZ-25.",
    "a line after the closing %": "X40.\n%\nG1 X60. Z-25.",
    "Arabic-Indic digits (X40)": "X\u0664\u0660.",
    "a repeated word (X10. X40.)": "X10. X40.",
    "F47.244 G20 (1200 mm/min)": "F47.244 G20\nG21 X40.",
    "a rapid through the plate": "X-40.\nG0 X40. Z-1.",
    "F1e9 written out (F1000000000)": "X40. F1000000000",
}


def main():
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, middle) in enumerate(CASES.items()):
            program = Path(tmp) / f"case{k + 1}.nc"
            program.write_bytes(PROGRAM.format(middle=middle).encode())
            scenario = Path(tmp) / "scenario.yaml"
            scenario.write_text(SCENARIO.format(program=program.name))
            try:
                sc = load_scenario(scenario)
            except InputError as e:
                print(f"{name}: refused: {str(e).replace(tmp + '/', '')}")
                continue
            path = planned_path(sc)
            p = path.positions(np.linspace(0.0, path.duration_s, 4000)) * 1e3
            warnings = getattr(getattr(sc, "_program", None), "warnings", [])
            print(f"{name}: runs: lowest z {p[:, 2].min():.1f} mm, largest x {p[:, 0].max():.1f} mm, feed "
                  f"{sc.path.feed_mm_per_s * 60:.1f} mm/min, {path.duration_s:.1f} s"
                  + "".join(f"; warning: {w.replace(tmp + '/', '')}" for w in warnings))
    return 0


if __name__ == "__main__":
    sys.exit(main())
