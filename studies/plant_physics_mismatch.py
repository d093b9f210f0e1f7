"""Compensation against physics it does not share: the face-and-contour
job (diagrams/face_and_contour.yaml) with the plant's own cutting law
(model/plant_cutting.py: the chip from the tool's actual motion, a Kienzle
chip law, the worn edge's ploughing, runout) and the preview compensator
on what a user measures (diagrams/user_measurements.py), and which
imperfection dominates what is left: each removed alone (the preview's
error with that one part made exact).

Prints: the runs' surface error (mean, RMS, max abs, mm) and the force
model's mismatch along the cut (the compensator's linear, revolution-
averaged model with its identified coefficients, at the plan's clock,
against the plant's force: RMS and largest |dF|, N, and RMS relative to
the plant's RMS force); then the preview's error with each imperfection
removed.

    python studies/plant_physics_mismatch.py     # about 10 runs, 5-10 minutes on a quiet 2-core machine
"""

import copy
import sys
from pathlib import Path

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.force_mismatch import force_model_mismatch
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "face_and_contour.yaml"


def exact_inertia(sc):
    sc.model.identification.inertia_error = 0.0


def stated_damping(sc):
    sc.model.identification.damping = "stated"


def exact_tcp(sc):
    sc.model.identification.tcp_error_mm = 0.0


def exact_probe(sc):
    sc.model.identification.probe_error_mm = 0.0


def linear_plant(sc):
    sc.cutting.plant_law = "linear"


def exact_coefficients(sc):
    sc.model.identification.coefficients = "exact"


def exact_stiffness(sc):
    sc.model.identification.stiffness = "exact"


REMOVALS = (("inertias (+-15 %)", exact_inertia), ("damping (modal test)", stated_damping),
            ("tool point (TCP calibration)", exact_tcp), ("workpiece top (probe)", exact_probe),
            ("plant's cutting law (Kienzle, wear, runout)", linear_plant),
            ("cutting coefficients (+-20 %)", exact_coefficients), ("joint stiffness (campaign)", exact_stiffness))


def run(sc, robot, compensation=True):
    res = run_cut(copy.deepcopy(sc), robot, compensation=compensation)
    s = res.surface_error_mm
    return s, force_model_mismatch(res)


def line(label, s, m=None):
    text = f"| {label} | {s['mean']:+.4f} | {s['rms']:.4f} | {s['max_abs']:.4f} |"
    if m is not None:
        text += f" {m['rms_N']:.1f} / {m['max_N']:.1f} ({100 * m['rms_rel']:.0f} %) |"
    print(text, flush=True)


def main():
    robot = load_robot()
    base = load_scenario(SCENARIO)
    print("face_and_contour.nc against the plant's own cutting law")
    print("| run | mean (mm) | RMS (mm) | max abs (mm) | force model mismatch RMS / max (N) |")
    print("|---|---|---|---|---|")
    s, m = run(base, robot, compensation=False)
    line("uncompensated", s, m)
    pv = copy.deepcopy(base)
    pv.controller.mode = "preview"
    s0, m0 = run(pv, robot)
    line("preview, identified model, user-measured", s0, m0)
    nominal = copy.deepcopy(pv)
    nominal.model.source = "nominal"
    line("preview, exact model (bound)", *run(nominal, robot))
    print("\nthe preview's error with one imperfection removed (the others kept)")
    print("| removed | mean (mm) | RMS (mm) | max abs (mm) | change of RMS (mm) |")
    print("|---|---|---|---|---|")
    for label, remove in REMOVALS:
        sc = copy.deepcopy(pv)
        remove(sc)
        s, _ = run(sc, robot)
        print(f"| {label} | {s['mean']:+.4f} | {s['rms']:.4f} | {s['max_abs']:.4f} | {s['rms'] - s0['rms']:+.4f} |",
              flush=True)
        print(f"  done: {label}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
