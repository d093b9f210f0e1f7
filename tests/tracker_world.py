"""Laser-tracker accuracy campaigns made by Drake's perturbed plant: the
generator is the package's (robstiff_drake/diagrams/tracker_world.py, the
one ``robstiff synth tracker`` runs); the tests and studies import it from
here as before."""

from robstiff_drake.diagrams.tracker_world import *  # noqa: F401,F403
from robstiff_drake.diagrams.tracker_world import Arm, TrackerWorld, make_tracker_campaign  # noqa: F401

if __name__ == "__main__":  # python3 tests/tracker_world.py ROBOT SEED N OUT.csv
    import sys

    import numpy as np

    from robstiff_drake.model.robot import load_robot

    name, seed, n, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    c = make_tracker_campaign(load_robot(name), seed, n=n)
    with open(out, "x") as f:
        f.write(c.csv_text)
    print(f"{out}: {n} rows; planted {c.true['effects']}; measured point {np.round(c.true['tool_mm'], 3)} mm")
