"""The preview table's background build (cell/preview_cache.py): run as
``python -m robstiff_drake.cell.preview_build`` by
cell/preview_job.BackgroundTable, its inputs as JSON on stdin
(preview_cache.build_input), the table written to the cache file."""

import json
import sys

import numpy as np

from robstiff_drake.cell import preview_cache
from robstiff_drake.cell.preview_job import build_plan, load_job
from robstiff_drake.errors import InputError


def main():
    """The background build: the job's table into the cache file; exit status 0, or 2 with one line."""
    spec = json.loads(sys.stdin.read())
    try:
        sc, robot = load_job(spec["job"], spec["robot"], period_s=spec["period_s"])
        plan = build_plan(sc, robot, np.asarray(spec["k"]), period_s=spec["period_s"],
                          filter_ba=tuple(np.asarray(x) for x in spec["filter_ba"]), rate_hz=spec["rate_hz"],
                          delay_steps=spec["delay_steps"], servo_option=spec["servo"])
    except InputError as e:
        print(f"robstiff: error: {e}", file=sys.stderr)
        return 2
    if not preview_cache.save(plan, spec["file"]):
        print(f"robstiff: error: cannot write the preview's table to {spec['file']}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
