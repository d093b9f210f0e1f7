"""Gear play in the plant, the compensator's lost-motion laws and
`diagnose-run`: how well the laws fit the play, and what the diagnosis
concludes.

The plant's gears have play (model/transmission.play_torque): a dead zone
of total width 2b, no torque inside it but the friction, the link left on
the flank it last pressed until the torque passes the friction the other
way.  The compensator's model has two laws (model.lost_motion_law): the
smooth phi = c tau + b tanh(tau / TAU_B_j) and the hysteretic one
(model/play_hysteresis.py: each gear's position in its gap from the
torque's history, the friction per joint); diagnose-run's `lost_motion`
cause keeps the smooth law.

1. The two laws at rest: the twist the smooth law gives against the play's
   (on the flank the torque presses), as a fraction of b, for a few
   torques.  The play is +-b as soon as the torque has a sign; the smooth
   law takes b up over about 100 N*m.
2. The pass of tests/data/balanced_y_pass.yaml (x = 1091.5 mm, along y at
   40 mm/s, predictive compensation), where joint 2's gear torque crosses
   zero during the cut (from about -55 to +77 N*m), with play b on joint 2
   alone, b = 0, 20, 40, 80, 150, 300 urad.  For each: the compensated
   surface error (the compensator without lost motion), the same with the
   compensator's smooth law and with its hysteretic law at the true b (how
   well each law fits the play plant; the friction is the fallback, the
   plant's own 1.5 % of the rated torque: a perfect-model bound), and `diagnose-run` on the first run with 3 um of scan noise: the
   causes it names (and b2 fitted), the arm's damping it reads, and the
   verdict of its verification cuts (each candidate fix cut once more on
   the same simulated machine, decided from the cuts' scans only; see
   studies/run_diagnosis_cases.py).  Last column, the play's share: the
   rms of each compensated face less the face of the pass without play
   (same compensator, b = 0), point by point: what the play and each
   law's miss of it leave, apart from the loop's own tracking error (which
   the play's uncompensated undercut can happen to cancel).

    python3 studies/play_diagnosis.py [--out DIR] [--b-urad 0,20,40,80,150,300]
"""

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from run_diagnosis_cases import _quiet, close_loop, traced  # noqa: E402

from robstiff_drake.model import transmission  # noqa: E402
from robstiff_drake.paths import REPO_ROOT  # noqa: E402

BALANCED = (REPO_ROOT / "tests" / "data" / "balanced_y_pass.yaml").read_text()
TORQUES_NM = (5.0, 10.0, 25.0, 50.0, 100.0, 150.0)


def predictive(text):
    return text.replace("controller:\n", "controller:\n  mode: predictive\n", 1)


def with_play(text, b_rad, section="plant", law=None):
    line = f"  lost_motion_rad: [0.0, {b_rad:g}, 0.0, 0.0, 0.0, 0.0]\n"
    if law:
        line += f"  lost_motion_law: {law}\n"
    return text.replace(f"{section}:\n", f"{section}:\n{line}", 1) if section in text else text + f"{section}:\n{line}"


def surface(folder, name, text):
    """The compensated run's surface statistics (mm) from its summary."""
    import json

    sc = folder / f"{name}.yaml"
    sc.write_text(text)
    if _quiet(["simulate", str(sc), "--compensation", "on", "--out", str(folder / name)]) != 0:
        raise SystemExit(f"simulate {sc} failed")
    summary = json.loads((folder / name / "summary.json").read_text())
    return summary["surface_error_mm"]["compensated"]


def face(folder, name):
    """The compensated run's machined-face error along the pass (mm, NaN off the face) of ``surface``'s run."""
    rows = np.genfromtxt(folder / name / "sim_surface_compensated.csv", delimiter=",", names=True, skip_header=2)
    return rows["error_mm"]


def play_share(e, e0):
    """rms of the face less the face without play (mm): what the play (and a law's miss of it) leaves."""
    d = (e - e0)[~np.isnan(e - e0)]
    return float(np.sqrt(np.mean(d ** 2)))


def laws_table():
    print("1. The smooth law against the play at rest: (twist of the smooth law - twist of the play) / b, on the "
          "flank the torque presses (both laws share the elastic part c tau)")
    print("| torque (N*m) | " + " | ".join(f"{t:g}" for t in TORQUES_NM) + " |")
    print("|---|" + "---|" * len(TORQUES_NM))
    c = np.full(6, 1.0 / 1.1e6)
    b = np.full(6, 1e-4)
    row = []
    for tau in TORQUES_NM:
        t = np.full(6, tau)
        smooth = transmission.twist(t, c, b)[1]
        play = transmission.play_twist(t, c, b)[1]
        row.append(f"{(smooth - play) / b[1]:+.3f}")
    print("| (smooth - play) / b | " + " | ".join(row) + " |")
    print()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--b-urad", default="0,20,40,80,150,300")
    args = ap.parse_args()
    laws_table()
    out = Path(args.out or tempfile.mkdtemp(prefix="robstiff-play-"))
    out.mkdir(parents=True, exist_ok=True)
    print("2. The balanced pass with play b on joint 2 (predictive compensation); surface error mean / rms / max abs "
          "(mm)")
    print("| b2 (urad) | compensator without lost motion | compensator's smooth law at the true b | compensator's "
          "hysteretic law at the true b | diagnose-run: traced (fitted) | the arm's damping it used | decided from "
          "the verification cuts | after the decided fix (mm) | the play's share: rms of the face less the face "
          "without play, without lost motion / smooth / hysteretic (mm) |")
    print("|---|---|---|---|---|---|---|---|---|")
    base = predictive(BALANCED)
    surface(out, "no_play_face", base)
    e0 = face(out, "no_play_face")
    for b_urad in (float(v) for v in args.b_urad.split(",")):
        b = b_urad * 1e-6
        text = with_play(base, b) if b else base
        name = f"play_{b_urad:g}"
        rep, verified, _ = close_loop(text, out, name)
        s0 = rep["surface_error_before_mm"]
        laws = {"smooth": "-", "hysteretic": "-"}
        share = "-"
        if b:
            surface(out, f"{name}_no_law", text)
            shares = [play_share(face(out, f"{name}_no_law"), e0)]
            for law in laws:
                s1 = surface(out, f"{name}_{law}_law", with_play(text, b, "model", law))
                laws[law] = f"{s1['mean']:+.4f} / {s1['rms']:.4f} / {s1['max_abs']:.4f}"
                shares.append(play_share(face(out, f"{name}_{law}_law"), e0))
            share = " / ".join(f"{v:.4f}" for v in shares)
        d = rep["damping"]
        damping = f"{d['used']:.0%} ({'from the run' if d.get('ratio') is not None else 'assumed'})"
        if verified is None:
            decided, after = (rep["fix"]["status"] if rep["fix"] else "nothing to verify"), "-"
        else:
            fix = verified["fix"]
            decided = fix["candidate"] or fix["status"]
            rows = {r["candidate"]: r["surface_error_mm"] for r in verified["verification"]["cuts"]}
            a = rows[verified["verification"]["best"]]
            after = f"{a['mean']:+.4f} / {a['rms']:.4f} / {a['max_abs']:.4f}"
        print(f"| {b_urad:g} | {s0['mean']:+.4f} / {s0['rms']:.4f} / {s0['max_abs']:.4f} | {laws['smooth']} | {laws['hysteretic']} | {traced(rep)} | "
              f"{damping} | {decided} | {after} | {share} |", flush=True)
    if args.out is None:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
