"""The machining-run loop closed three times, with scan noise and decisions
from measured scans only: a compensated cut whose plant carries something
the compensator lacks is simulated (`robstiff simulate`), `robstiff
diagnose-run` traces the residual from the run's cell files (wrench log,
joint log, compensator settings, scan with 3 um noise), writes each
candidate fix as compensator settings, each candidate is cut once more on
the same simulated machine (`robstiff simulate RUN/sim_scenario.yaml
--compensator CANDIDATE.yaml`, new sensor and scan noise), and
`robstiff diagnose-run RUN --verify CUT ...` decides from the cuts' scans
(the simulation's truth files are deleted before it runs).

  softer_joint_3      block test (plain compensation), the plant's joint 3 20 % softer than
                      the model
  lost_motion         tests/data/balanced_y_pass.yaml (predictive compensation): a pass along
                      y where joint 2 carries almost none of the arm's weight, 40 urad of gear
                      play (a dead zone) on joints 1-3 (joint 1's moves the tool sideways,
                      joint 3's gear never leaves its loaded flank: only joint 2's shows on the
                      face); diagnose-run's law is the smooth one (studies/play_diagnosis.py)
  loop_lag            interrupted_cut, plain compensation at a 24 ms period
  lost_motion_loaded  block test (predictive), 40 urad of play on joints 2-3, which carry kN*m of the
                      arm's weight: physically invisible on the face, nothing to name

Prints the before/after table (docs/run_diagnosis.md); writes each case's
folders under OUT (default: a temporary folder, removed afterwards) and the
plots to docs/ with --docs.

    python3 studies/run_diagnosis_cases.py [--docs] [--out DIR]
"""

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

from robstiff_drake.commands.main import main as robstiff
from robstiff_drake.identification.runs.tables import SIM_PREFIX
from robstiff_drake.paths import DIAGRAMS_DIR, REPO_ROOT



def nominal_model(text):
    """The scenario with the compensator on the robot file's nominal model
    (``model.source: nominal``): the cases' premise is a compensator that
    lacks exactly what the plant is given; the example scenarios in
    diagrams/ hold an identified model, which would learn it."""
    if "  source: nominal" in text:
        return text
    if "\nmodel:\n" in text:
        return text.replace("\nmodel:\n", "\nmodel:\n  source: nominal\n", 1)
    return text.rstrip("\n") + "\nmodel:\n  source: nominal\n"


BLOCK = nominal_model((DIAGRAMS_DIR / "block_milling.yaml").read_text())
BALANCED = (REPO_ROOT / "tests" / "data" / "balanced_y_pass.yaml").read_text()


def predictive(text):
    return text.replace("controller:\n", "controller:\n  mode: predictive\n", 1)


def lost_motion(text, b_urad):
    return text.replace("plant:\n", "plant:\n  lost_motion_rad: [" + ", ".join(f"{v * 1e-6:g}" for v in b_urad)
                        + "]\n", 1)


CASES = {
    "softer_joint_3": BLOCK.replace("plant:\n", "plant:\n  joint_stiffness_Nm_per_rad: [1.5e6, 1.1e6, 6.4e5, "
                                    "3.0e5, 3.0e5, 2.0e5]\n", 1),
    "lost_motion": lost_motion(predictive(BALANCED), [40, 40, 40, 0, 0, 0]),
    "loop_lag": nominal_model((DIAGRAMS_DIR / "interrupted_cut.yaml").read_text()),
    "lost_motion_loaded": lost_motion(predictive(BLOCK), [0, 40, 40, 0, 0, 0]),
}
VERIFY_SEED = 1000  # noise seeds of the verification cuts: 1000, 1001, ... (the first cut keeps the scenario's)


def _quiet(args):
    """robstiff(args) with its printout swallowed; its exit status."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        return robstiff(args)


def diagnose(run_dir, extra=()):
    """diagnose-run's JSON report (and the seconds it took)."""
    out = Path(run_dir).parent / f"{Path(run_dir).name}_diagnosis.json"
    t0 = time.perf_counter()
    code = _quiet(["diagnose-run", str(run_dir), "--json", str(out), "--out", str(Path(run_dir).parent /
                                                                               f"{Path(run_dir).name}_diagnosis"),
                   *extra])
    if code != 0:
        raise SystemExit(f"diagnose-run {run_dir} failed ({code})")
    return json.loads(out.read_text()), time.perf_counter() - t0


def close_loop(scenario_text, folder, name, *, scenario_seed=None):
    """Simulate, diagnose, cut each candidate fix on the same machine, and
    decide from the cuts' scans.  Returns (first report, verified report or
    None, diagnose-run seconds)."""
    folder = Path(folder)
    sc = folder / f"{name}.yaml"
    sc.write_text(scenario_text)
    run_dir = folder / name
    args = ["simulate", str(sc), "--compensation", "on", "--out", str(run_dir)]
    if scenario_seed is not None:
        args += ["--noise-seed", str(scenario_seed)]
    if _quiet(args) != 0:
        raise SystemExit(f"simulate {sc} failed")
    rep, seconds = diagnose(run_dir)
    cands = [c for c in rep.get("candidates", []) if "settings" in c]
    if not cands:
        return rep, None, seconds
    diag = folder / f"{name}_diagnosis"
    cuts = []
    for i, c in enumerate(cands):
        cut = folder / f"{name}_cut{i}"
        if _quiet(["simulate", str(run_dir / f"{SIM_PREFIX}scenario.yaml"), "--compensation", "on",
                   "--compensator", str(diag / c["settings"]), "--noise-seed", str(VERIFY_SEED + i),
                   "--out", str(cut)]) != 0:
            raise SystemExit(f"verification cut {cut} failed")
        cuts.append(cut)
    # the decision reads the run folders' cell files only: the truth goes first
    for p in [run_dir, *cuts]:
        for f in Path(p).glob(f"{SIM_PREFIX}*"):
            f.unlink()
    verified, _ = diagnose(run_dir, ["--verify", *map(str, cuts)])
    return rep, verified, seconds


def _fmt_params(p):
    return ", ".join(f"{k} = {v:.3g}" for k, v in p.items())


def traced(rep):
    """What the first cut traced, in words: the named causes (fitted), the
    alternatives, and the loop's tracking error when it matters."""
    causes = "; ".join(f"{c['name']} ({_fmt_params(c['params'])})" for c in rep["causes"]) or "no cause"
    alike = rep.get("also_consistent_with") or []
    if alike:
        causes += f"; as good on the one pass: {', '.join(alike)}"
    lag = rep["loop_lag"]
    if lag["status"] == "ok" and lag["significant"]:
        causes += (f"; the loop's tracking error (a = {lag['params']['a (x predicted)']:.2f}, "
                   f"{lag['size_mm']:.3f} mm" + (f", fix {lag['fix']}" if lag.get("fix") else ", no settings fix")
                   + ")")
    return causes


def table_row(name, rep, verified):
    causes = traced(rep)
    b = rep["surface_error_before_mm"]
    if verified is None:
        return (f"| {name} | {causes} | {rep['fix']['status'] if rep['fix'] else 'nothing to verify'} | - | "
                f"{b['mean']:+.3f} / {b['rms']:.3f} / {b['max_abs']:.3f} | - |")
    v = verified["verification"]
    fix = verified["fix"]
    decided = (f"{fix['candidate']}: {'; '.join(fix['changes'])}" if fix["candidate"]
               else f"{fix['status']} ({', '.join(fix.get('tied', []))})")
    rows = {r["candidate"]: r["surface_error_mm"] for r in v["cuts"]}
    a = rows[v["best"]]
    cut_rms = ", ".join(f"{k} {s['rms']:.4f}" for k, s in rows.items())
    return (f"| {name} | {causes} | {decided} | {cut_rms} | {b['mean']:+.3f} / {b['rms']:.3f} / {b['max_abs']:.3f} "
            f"(edges {b['edges_max_abs']:.3f}) | {a['mean']:+.3f} / {a['rms']:.3f} / {a['max_abs']:.3f} "
            f"(edges {a['edges_max_abs']:.3f}) |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--docs", action="store_true", help="copy the diagnosis plots to docs/")
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="robstiff-run-diagnosis-"))
    out.mkdir(parents=True, exist_ok=True)
    print("| case (what the plant has) | traced from the first cut (fitted) | decided from the verification cuts' "
          "scans | verification cuts: rms (mm) | before: mean / rms / max abs (mm) | "
          "after: mean / rms / max abs (mm) |")
    print("|---|---|---|---|---|---|")
    seconds = []
    for name, text in CASES.items():
        rep, verified, s = close_loop(text, out, name)
        seconds.append(s)
        print(table_row(name, rep, verified), flush=True)
        if args.docs:
            shutil.copy(out / f"{name}_diagnosis" / "diagnosis.png", REPO_ROOT / "docs" / f"run_diagnosis_{name}.png")
    print("\ndiagnose-run per run (first cut, in this process: without the 1-2 s of Python and Drake start-up): "
          + ", ".join(f"{s:.1f}" for s in seconds) + " s")
    if args.out is None:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
