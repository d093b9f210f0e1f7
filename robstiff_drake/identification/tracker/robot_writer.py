"""A corrected robot file: the user's robot file with the corrections a
tracker campaign's diagnosis kept (the chain's theta, d, a, alpha and
Hayati beta; the measured point as the tool point; the joint stiffness the
sag identified), their provenance as comments at its top, every other line
(and comment) as it was.  Plain text and PyYAML.

The canonical chain's corrections are written back in the file's own
convention: standard DH rows are the canonical links; a modified-DH file's
row i+1 holds standard link i's a, alpha and beta (model/robot.py's
_read_dh: row 1's a, alpha and beta are the base transform, which the
registration absorbs and the search does not correct).  A key that is a
one-line flow list (the library's style) is replaced in place; otherwise
the document is re-emitted by PyYAML (comments then kept only in the
header), which is said in the header.  The result is read back with the
project's reader and its forward kinematics checked against the fitted
model's before it is written (``check``).

The setup findings (setup_terms.py) the diagnosis kept are the user's
declarations, not the arm's: a payload mass or centre of mass found is
written as ``payload.mass_kg`` / ``payload.com_mm`` (the fit's sag is the
file's masses through its compliances: the two together reproduce it) and
read back; a gravity turned from the instrument's vertical has no key in a
robot file (the tracker diagnosis takes the vertical from the instrument's
frame, not from the robot file), so the header says what was found and
what to do instead of writing it.
"""

import re
from datetime import date

import numpy as np
import yaml

from robstiff_drake.errors import InputError
from robstiff_drake.identification.tracker.model import GEOM, perturbed_dh
from robstiff_drake.io import write_atomic

CHECK_TOL_M = 1e-9


def _row_values(robot, doc_dh, geo):
    """{key: new list} of the file's dh table with the canonical deltas (6, 5) added."""
    mod = robot.convention == "modified_dh"
    out = {k: [float(v) for v in doc_dh[k]] for k in ("d_mm", "a_mm", "alpha_deg", "home_deg")}
    out["beta_deg"] = [float(v) for v in doc_dh.get("beta_deg", [0.0] * 6)]
    for k in range(6):
        dtheta, dd, da, dalpha, dbeta = geo[k]
        row = k + 1 if mod else k  # where standard link k's a, alpha, beta live in the file
        out["home_deg"][k] += float(np.rad2deg(dtheta))
        out["d_mm"][k] += float(dd * 1e3)
        if da or dalpha or dbeta:
            if row > 5:
                raise ValueError(f"link {k + 1}'s a, alpha, beta have no row in a modified-DH table")
            out["a_mm"][row] += float(da * 1e3)
            out["alpha_deg"][row] += float(np.rad2deg(dalpha))
            out["beta_deg"][row] += float(np.rad2deg(dbeta))
    if not any(out["beta_deg"]):
        out.pop("beta_deg")
    return out


def _number(v):
    v = float(v)
    return f"{v:.1f}" if v == int(v) and abs(v) < 1e6 else f"{v:.12g}"


def _flow(values):
    return "[" + ", ".join(_number(v) for v in values) + "]"


def _replace_line(text, key, values, after=None):
    """Replace a one-line flow list ``key: [...]`` (keeping its indentation
    and trailing comment); insert it after the line of ``after`` when the
    key is missing.  Returns the new text, or None when it cannot."""
    pat = re.compile(rf"^([ \t]*){re.escape(key)}:[ \t]*\[[^\]\n]*\][ \t]*(#.*)?$", re.M)
    m = list(pat.finditer(text))
    if len(m) == 1:
        g = m[0]
        tail = f"  {g.group(2)}" if g.group(2) else ""
        return text[:g.start()] + f"{g.group(1)}{key}: {_flow(values)}{tail}" + text[g.end():]
    if not m and after is not None:
        a = list(re.compile(rf"^([ \t]*){re.escape(after)}:[ \t]*\[[^\]\n]*\].*$", re.M).finditer(text))
        if len(a) == 1:
            g = a[0]
            return text[:g.end()] + f"\n{g.group(1)}{key}: {_flow(values)}" + text[g.end():]
    return None


def _section_span(text, section):
    """(start, end) of the lines below the top-level ``section:`` (to the next top-level key), or None."""
    m = list(re.finditer(rf"^{re.escape(section)}:[ \t]*(#.*)?$", text, re.M))
    if len(m) != 1:
        return None
    nxt = re.compile(r"^[^\s#]", re.M).search(text, m[0].end())
    return m[0].end(), nxt.start() if nxt else len(text)


def _replace_in_section(text, section, key, value_text, flow):
    """Replace the value of ``section``'s ``key`` (a one-line flow list when ``flow``, else a plain scalar),
    keeping its indentation and trailing comment; None when it cannot."""
    span = _section_span(text, section)
    if span is None:
        return None
    value = r"\[[^\]\n]*\]" if flow else r"[-+0-9.eE]+"
    pat = re.compile(rf"^([ \t]+){re.escape(key)}:[ \t]*{value}[ \t]*(#.*)?$", re.M)
    m = list(pat.finditer(text, *span))
    if len(m) != 1:
        return None
    g = m[0]
    tail = f"  {g.group(2)}" if g.group(2) else ""
    return text[:g.start()] + f"{g.group(1)}{key}: {value_text}{tail}" + text[g.end():]


def _as_found(key, value, declared, finding, confirm, unseparated):
    """A payload key's header line: ``value`` as the campaign's sag found it against the ``declared`` one,
    beyond or within the typical, then ``confirm``, and ``unseparated`` where the data do not separate the
    finding from its alternatives."""
    typical = "; a SETUP FINDING beyond the typical" if finding["beyond_typical"] else "; within the typical"
    return (f"payload.{key}: {value}, as the campaign's sag found it (the original declares {declared}{typical})"
            + confirm + ("" if finding["separated"] else unseparated))


def setup_corrections(robot, report):
    """What the setup findings kept (setup_terms.py) write into the file: ({payload key: value}, [header
    lines]).  The payload's mass and centre of mass as the fit found them; a gravity turned from the
    vertical only as a header note (no robot file key holds it)."""
    found = {f["name"]: f for f in report.get("setup_findings") or []}
    keys, notes = {}, []
    pl = robot.payload
    if "payload_mass" in found:
        f = found["payload_mass"]
        mass = float(f"{pl.mass_kg + f['estimate']['dm (kg)']:.6g}")
        keys["mass_kg"] = mass
        notes.append(_as_found("mass_kg", f"{_number(mass)} kg", f"{_number(pl.mass_kg)} kg", f,
                               ": weigh the tool to confirm",
                               " (the data do not separate it from the joints' compliance scale: see the diagnosis)"))
    if "payload_com" in found:
        f = found["payload_com"]
        est = f["estimate"]
        com = [float(f"{c * 1e3 + est[f'd{a} (mm)']:.6g}") for c, a in zip(pl.com_m, "xyz")]
        keys["com_mm"] = com
        notes.append(_as_found("com_mm", f"{_flow(com)} mm", f"{_flow(pl.com_m * 1e3)} mm", f, "",
                               "; the data do not separate it from its alternatives (see the diagnosis): run the "
                               "controller's load identification to confirm"))
    if "gravity_tilt" in found:
        f = found["gravity_tilt"]
        e = f["estimate"]
        notes.append(f"NOT WRITTEN (no robot file key holds it): the gravity the arm felt was turned by "
                     f"{float(np.hypot(e['tilt_x (deg)'], e['tilt_y (deg)'])):.2g} deg from the instrument's "
                     f"vertical (about the base's x {e['tilt_x (deg)']:+.2g} deg, y {e['tilt_y (deg)']:+.2g} deg). "
                     "The diagnosis takes the vertical from the tracker's frame: level the tracker (or export the "
                     "points in a levelled frame) and measure again; this file's sag is the arm's own, without it")
    return keys, notes


def periodic_entries(fit):
    """[{joint (1-based), period_deg, sin_mrad, cos_mrad}] of the fit's periodic blocks."""
    out = []
    for b in fit.blocks:
        v = fit.coef.get(b.name)
        for i, t in enumerate(getattr(b, "periodic", None) or []):
            out.append({"joint": int(t["joint"]) + 1, "period_deg": float(f"{t['period_deg']:.8g}"),
                        "sin_mrad": float(f"{v[2 * i] * 1e3:.6g}"), "cos_mrad": float(f"{v[2 * i + 1] * 1e3:.6g}")})
    return out


def _periodic_text(entries):
    head = ["", "# angle errors periodic in each joint's controller angle (reducer, encoder), from the tracker",
            "# campaign: error = 1e-3 (sin_mrad sin(2 pi q / period) + cos_mrad cos(2 pi q / period)) rad",
            "joint_periodic_errors:"]
    items = [f"  - {{joint: {e['joint']}, period_deg: {_number(e['period_deg'])}, sin_mrad: {_number(e['sin_mrad'])}, "
             f"cos_mrad: {_number(e['cos_mrad'])}}}" for e in entries]
    return "\n".join(head + items) + "\n"


def corrected_text(robot, source_text, fit, k_Nm_per_rad, provenance, payload=None):
    """The corrected robot file's text (see the module docstring); ``payload``: {payload key: value} the
    setup findings correct (setup_corrections)."""
    doc = yaml.safe_load(source_text)
    payload = payload or {}
    periodic = periodic_entries(fit)
    rows = _row_values(robot, doc["dh"], fit.geo)
    tool = [float(v) for v in fit.u * 1e3]
    k = [float(f"{v:.6g}") for v in k_Nm_per_rad]
    text, inline = source_text, True
    for key, vals in rows.items():
        new = _replace_line(text, key, vals, after="home_deg" if key == "beta_deg" else None)
        inline &= new is not None
        text = new if new is not None else text
    if "beta_deg" not in rows and "beta_deg" in doc["dh"]:
        new = _replace_line(text, "beta_deg", [0.0] * 6)
        inline &= new is not None
        text = new if new is not None else text
    # the tracker's target has its own key: the machining tool point (tool_point_mm) stays as it was
    new = _replace_line(text, "measured_point_mm", tool,
                        after="tool_point_mm" if re.search(r"^[ \t]*tool_point_mm:", text, re.M) else "com_mm")
    inline &= new is not None
    text = new if new is not None else text
    new = _replace_line(text, "joint_stiffness_Nm_per_rad", k)
    inline &= new is not None
    text = new if new is not None else text
    for key, value in payload.items():
        new = _replace_in_section(text, "payload", key, _flow(value) if isinstance(value, list) else _number(value),
                                  flow=isinstance(value, list))
        inline &= new is not None
        text = new if new is not None else text
    if periodic and "joint_periodic_errors" in doc:  # a corrected file corrected again: the new terms add
        inline = False
    elif periodic:
        text = text.rstrip("\n") + "\n" + _periodic_text(periodic)
    if not inline:
        if periodic:
            doc["joint_periodic_errors"] = list(doc.get("joint_periodic_errors") or []) + periodic
        doc["dh"].update(rows)
        if "beta_deg" not in rows:
            doc["dh"].pop("beta_deg", None)
        doc["payload"]["measured_point_mm"] = tool
        doc["payload"].update(payload)
        doc["joint_stiffness_Nm_per_rad"] = k
        text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
        provenance = provenance + ["the original's comments are in its own file (this one was re-emitted by PyYAML)"]
    head = "".join(f"# {line}\n" for line in provenance)
    return head + "#\n" + text


def provenance_lines(data, robot, report, corrections):
    e = report["error_3d_mm"]
    lines = [f"Corrected by `robstiff diagnose {data} --write-robot` on {date.today().isoformat()} from the robot file "
             f"{robot.source} and the tracker campaign {data} ({report['n_used']} rows).",
             f"Held-out 3D error ({e['held_out']}): mean {e['before']['mean']:.4f} mm, "
             f"rms {e['before']['rms']:.4f} mm, "
             f"max {e['before']['max']:.4f} mm with the nominal arm; mean {e['after']['mean']:.4f} mm, rms "
             f"{e['after']['rms']:.4f} mm, max {e['after']['max']:.4f} mm with these corrections.",
             "Kept: " + (", ".join(report["selected_effects"]) or "nothing") + "; written here: "
             + ", ".join(corrections)
             + ". Effects of the instrument or the session (drift, thermal) are in the diagnosis's report, not here.",
             "measured_point_mm is the measured point (the tracker's target) on the flange; tool_point_mm, the "
             "machining tool point, is the original's."]
    return lines


def check(path, robot_fit, fit, q_rad, payload=None):
    """Read the written file back and compare its forward kinematics (flange
    and tool point) with the fitted model's at ``q_rad`` (N, 6) model angles,
    and its payload with ``payload`` ({mass_kg, com_mm} written); InputError
    when they differ by more than CHECK_TOL_M (its payload: by more than 1e-6 kg or mm)."""
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.robot import load_robot

    new = load_robot(str(path))
    q_ctrl = robot_fit.joint_map.to_controller(q_rad)
    e = np.zeros_like(q_ctrl)  # the fit's periodic errors, in the controller's angles
    for t in periodic_entries(fit):
        nu = 360.0 / t["period_deg"]
        j = t["joint"] - 1
        e[:, j] += 1e-3 * (t["sin_mrad"] * np.sin(nu * q_ctrl[:, j]) + t["cos_mrad"] * np.cos(nu * q_ctrl[:, j]))
    want = kin.tool_position(perturbed_dh(robot_fit.dh, fit.geo), q_rad + e @ robot_fit.joint_map.G.T, fit.u)
    got = kin.tool_position(new.dh, new.joint_map.to_model(q_ctrl), new.payload.measured_point_m)
    err = float(np.max(np.abs(got - want)))
    if err > CHECK_TOL_M:
        raise InputError(f"{path}: the corrected robot file's kinematics differ from the fitted model's by "
                         f"{err * 1e3:.3g} mm (not written correctly; please report)")
    got = {"mass_kg": float(new.payload.mass_kg), "com_mm": list(new.payload.com_m * 1e3)}
    for key, value in (payload or {}).items():
        if np.max(np.abs(np.subtract(got[key], value))) > CHECK_TOL_M * 1e3:
            raise InputError(f"{path}: the corrected robot file's payload.{key} reads back as {got[key]}, not "
                             f"{value} (not written correctly; please report)")
    return err


def write_corrected_robot(out, robot, fit, report, data, q_rad):
    """Write the corrected robot file ``out`` (atomically; checked before)."""
    try:
        source_text = open(robot.source, encoding="utf-8").read()
    except OSError as e:
        raise InputError(f"{robot.source}: cannot read the robot file to correct ({e.strerror})") from None
    corrections = []
    if np.any(fit.geo):
        names = sorted({GEOM[j] for k in range(6) for j in range(5) if fit.geo[k, j]}, key=GEOM.index)
        corrections.append("the chain's " + ", ".join(names))
    corrections += ["measured_point_mm"]
    if "joint_compliance" in report["selected_effects"]:
        corrections.append("joint_stiffness_Nm_per_rad (the sag's)")
    if periodic_entries(fit):
        corrections.append("joint_periodic_errors")
    payload, notes = setup_corrections(robot, report)
    corrections += [f"payload.{key} (a setup finding)" for key in payload]
    text = corrected_text(robot, source_text, fit, report["joint_stiffness_Nm_per_rad"],
                          provenance_lines(data, robot, report, corrections) + notes, payload)
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        trial = Path(tmp) / Path(out).name
        trial.write_text(text, encoding="utf-8")
        err = check(trial, robot, fit, q_rad, payload)
    write_atomic(out, text)
    return err
