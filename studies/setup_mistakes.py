"""Setup mistakes planted in data the diagnosis did not make: what `diagnose`
names.  Two campaigns: the real FANUC R-2000iC campaign (43 loads by a third
party, tests/realdata.py; its copy in a temporary folder, the data never
written into the repository; skipped with the reason when absent) and a
campaign of Drake's plant (tests/setup_errors.py, kind "none": 30 poses x 4
loads of 300 N, CMM noise 0.01 mm).  Into each, one mistake at a time, as
a user makes them: the declared tool point off by 5, 20, 100 mm along the
flange's x or z; an untared force (a constant 20, 50, 200 N on fx) or
moment (5, 20 N*m on mx, moment columns added); forces in kN, lbf or kgf
written as N; displacements in inches written as mm; fy with the wrong sign; q2 or q5 written in radians; the
columns q2/q3 or q5/q6 interchanged; the displacements in a frame turned
1 deg about z.  Per case: the held-out RMS before and after, the terms
kept (* beyond the typical size, with its finding), the file read another
way (identification/diagnosis/misreadings.py), the best lead, or the
refusal; for the clean and the unit rows the joints' stiffness against the
robot file's and the unit warning identify and diagnose give
(identification/stiffness/unit_scale.py).  Noise stated: 0.03 mm for FANUC (a tracker's), 0.01 mm for Drake.

Run: python3 studies/setup_mistakes.py [--only fanuc|drake] [--docs]
(--docs replaces the setup_mistakes block of docs/diagnosis.md)
"""

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from generated_blocks import write_block  # noqa: E402
import realdata  # noqa: E402
import setup_errors as se  # noqa: E402

from robstiff_drake.errors import InputError  # noqa: E402
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose  # noqa: E402
from robstiff_drake.identification.stiffness.joint_stiffness import identify  # noqa: E402
from robstiff_drake.identification.stiffness.unit_scale import INCH_MM, KGF_N, LBF_N, unit_scale_note  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402



def _forces(c, f=None, m=None):
    return replace(c, force_N=c.force_N if f is None else f,
                   **({} if m is None else {"moment_Nm": m, "has_moments": True}))


def _col(a, k, fn):
    a = a.copy()
    a[:, k] = fn(a[:, k])
    return a


def cases():
    """[(label, campaign, tool_m) -> (campaign, tool_m)]."""
    out = [("clean", lambda c, t: (c, t))]
    for ax, k in (("x", 0), ("z", 2)):
        for mm in (5, 20, 100):
            out.append((f"tool point {mm} mm off along {ax}", lambda c, t, k=k, mm=mm: (c, t + np.eye(3)[k] * mm * 1e-3)))
    for b in (20, 50, 200):
        out.append((f"untared fx +{b} N", lambda c, t, b=b: (_forces(c, _col(c.force_N, 0, lambda v: v + b)), t)))
    for b in (5, 20):
        out.append((f"untared mx +{b} N*m", lambda c, t, b=b: (
            _forces(c, m=_col(np.zeros_like(c.force_N), 0, lambda v: v + b)), t)))
    out += [("forces in kN written as N", lambda c, t: (_forces(c, c.force_N * 1e-3), t)),
            ("forces in lbf written as N", lambda c, t: (_forces(c, c.force_N / LBF_N), t)),
            ("forces in kgf written as N", lambda c, t: (_forces(c, c.force_N / KGF_N), t)),
            ("displacements in inches written as mm", lambda c, t: (replace(c, disp_mm=c.disp_mm / INCH_MM), t)),
            ("fy with the wrong sign", lambda c, t: (_forces(c, _col(c.force_N, 1, np.negative)), t))]
    for j in (2, 5):
        out.append((f"q{j} in radians", lambda c, t, j=j: (replace(c, q_deg=_col(c.q_deg, j - 1, np.deg2rad)), t)))
    for a, b in ((2, 3), (5, 6)):
        out.append((f"q{a}/q{b} interchanged", lambda c, t, a=a, b=b: (
            replace(c, q_deg=c.q_deg[:, [b - 1 if i == a - 1 else a - 1 if i == b - 1 else i for i in range(6)]]), t)))
    r = np.deg2rad(1.0)
    R = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    out.append(("displacement frame turned 1 deg", lambda c, t: (replace(c, disp_mm=c.disp_mm @ R.T), t)))
    return out


def said(robot, campaign, tool_m, noise_mm, scale=False):
    """One line: what the diagnosis says of the campaign."""
    try:
        d = diagnose(robot, campaign, tool_m=tool_m, noise_mm=noise_mm)
    except InputError as e:
        return f"refused: {str(e).split(': ', 1)[1][:190]}".replace("|", "\\|")
    kept = ", ".join(t["name"] + ("*" if t["beyond_typical"] else "") for t in d.terms) or "none"
    s = f"{d.rms_before_mm:.4f} -> {d.rms_after_mm:.4f} mm; explains {d.explains_data}; kept: {kept}"
    finds = [t["finding"].split(":")[0] for t in d.terms if t.get("finding")]
    if finds:
        s += f" ({'; '.join(finds)})"
    misread = getattr(d, "misreadings", [])  # (absent before identification/diagnosis/misreadings.py)
    if misread:
        s += "; read another way: " + ", ".join(f"{m['name']}{'' if m['decisive'] else ' (possible)'} "
                                                f"({m['held_out_mm']:.4f} mm)" for m in misread[:3])
    if d.leads:
        lead = d.leads[0]
        est = ", ".join(f"{k.split(' ')[0]} {v:.3g}" for k, v in list(lead["params"].items())[:3])
        s += f"; best lead: {lead['name']} ({lead['rms_mm']:.4f} mm; {est})"
    if scale:  # the joints' stiffness against the robot file's (a common force scale shows only there)
        r = np.asarray(d.joint_stiffness_Nm_per_rad) / np.asarray(robot.joint_stiffness_Nm_per_rad)
        s += f"; stiffness {r.min():.2f}-{r.max():.2f}x the robot file's"
        fit = identify(robot, campaign, tool_m=tool_m)  # (what identify and diagnose warn: unit_scale.py)
        note = unit_scale_note(fit.stiffness_Nm_per_rad, robot.joint_stiffness_Nm_per_rad, fit.identifiable, "", "")
        s += "; warns: " + note.split("possibly ", 1)[1].split(", or the file")[0] if note else "; no unit warning"
    return s


SCALED = ("clean", "forces in lbf written as N", "forces in kgf written as N", "displacements in inches written as mm")


def table(title, robot, campaign, tool_m, noise_mm):
    lines = [title, "", "| planted | what `diagnose` says |", "|---|---|"]
    for label, plant in cases():
        c, t = plant(campaign, tool_m)
        lines.append(f"| {label} | {said(robot, c, t, noise_mm, label in SCALED)} |")
        print(lines[-1], flush=True)
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=["fanuc", "drake"])
    ap.add_argument("--docs", action="store_true", help="replace the setup_mistakes block of docs/diagnosis.md")
    args = ap.parse_args()
    out = []
    if args.only in (None, "fanuc"):
        reason = realdata.missing(realdata.FANUC)
        if reason:
            print(f"skipped FANUC: {reason}")
        else:
            with tempfile.TemporaryDirectory() as tmp:
                robot, campaign, tool_m, _ = realdata.fanuc_campaign(Path(tmp) / "fanuc.csv")
                out += table("FANUC R-2000iC (real, 43 loads; noise 0.03 mm stated)", robot, campaign, tool_m, 0.03)
            out.append("")
    if args.only in (None, "drake"):
        c = se.make_campaign("none", 11)
        out += table("Drake's plant (IRB 6400, 120 rows; noise 0.01 mm stated)", load_robot(), c.campaign,
                     np.asarray(c.declared_tool_m, dtype=float), se.NOISE_MM)
    if args.docs:
        write_block(ROOT / "docs" / "diagnosis.md", "setup_mistakes", "\n".join(out).rstrip())


if __name__ == "__main__":
    main()
