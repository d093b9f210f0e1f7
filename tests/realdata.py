"""Where the real third-party measurements are (``../shared/realdata`` next
to the repository, or $ROBSTIFF_REALDATA), and the FANUC R-2000iC campaign
in this project's campaign format.  Tests skip, and studies stop, with a
printed reason when the folder is absent; nothing here copies the data into
the repository (the converted campaign goes to a folder the caller gives).
"""

import os
from pathlib import Path

import numpy as np

ENV = "ROBSTIFF_REALDATA"
FANUC = "fanuc_r2000ic"
# The source's tool point (flange frame, m -> mm), from its README
FANUC_TOOL_MM = (6.9, 245.3, 319.3)
FANUC_ROBOT = "r2000ic_165f"


def realdata_dir():
    """The realdata folder: $ROBSTIFF_REALDATA, else <repo root>/../shared/realdata."""
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    return Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


def missing(name):
    """None when the data set ``name`` is there, else the reason it is not."""
    folder = realdata_dir() / name
    if not folder.is_dir():
        return f"real data {name} not found at {folder} (set {ENV} to the realdata folder)"
    return None


def require(name):
    """In a test: skip it, the reason printed, when the data set ``name`` is not there (``missing``)."""
    import pytest

    reason = missing(name)
    if reason:
        print(f"skipped: {reason}")
        pytest.skip(reason)


def fanuc_campaign_csv(out_path):
    """Write the FANUC campaign as a stiffness campaign (q1..q6 in FANUC's
    degrees, forces N, displacements mm, base frame; one pose per row; no
    seq column: the source does not give the measurement order) with the
    source's tool point in its '# tool_mm:' line.  Returns the path."""
    folder = realdata_dir() / FANUC
    q = np.loadtxt(folder / "joint_angles.csv", delimiter=",", skiprows=1)  # rad, FANUC's J1..J6
    f = np.loadtxt(folder / "forces.csv", delimiter=",", skiprows=1)  # N, base frame
    d = np.loadtxt(folder / "deltaX.csv", delimiter=",", skiprows=1)  # m, base frame
    lines = [f"# FANUC R-2000iC campaign of {folder} (MIT; see its README), converted by tests/realdata.py",
             "# tool_mm: " + ", ".join(f"{v:g}" for v in FANUC_TOOL_MM),
             "pose,q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz"]
    for i in range(len(q)):
        lines.append(",".join([f"P{i + 1:02d}"] + [f"{v:.10g}" for v in np.rad2deg(q[i])]
                              + [f"{v:.10g}" for v in f[i]] + [f"{v:.10g}" for v in d[i] * 1e3]))
    out_path = Path(out_path)
    out_path.write_text("\n".join(lines) + "\n")
    return out_path


def fanuc_campaign(out_path):
    """(robot, StiffnessCampaign, tool point m, path): the FANUC campaign
    written to ``out_path`` (fanuc_campaign_csv) and read on its robot file
    with its source's tool point, as the tests and studies diagnose it."""
    from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
    from robstiff_drake.model.robot import load_robot

    path = fanuc_campaign_csv(out_path)
    robot = load_robot(FANUC_ROBOT)
    return robot, read_stiffness_campaign(str(path), robot), np.array(FANUC_TOOL_MM) * 1e-3, path


IPA_UR10 = "ipa_ur10"
IPA_SERIES = {"A": "Series_A/measurements_grid.csv", "B": "Series_B/measurements_joint_configurations.csv"}


def _decimal_comma(cell):
    return float(cell.replace(",", "."))


def ipa_ur10_tool_mm(series="A"):
    """The probe's point on the flange (mm, flange frame) from the series'
    Trafo_TM_F_init.txt (the flange's pose in the probe's frame): -R^T t."""
    T = np.loadtxt(realdata_dir() / IPA_UR10 / f"Series_{series}" / "Trafo_TM_F_init.txt")
    return -T[:3, :3].T @ T[:3, 3]


def ipa_ur10_campaign_csv(series, out_path):
    """Write an IPA UR10 series (``"A"`` or ``"B"``) as an absolute-position
    campaign: q1..q6 the controller's degrees (UR's angles are its DH
    angles), x, y, z the tracker's measured probe point (mm, tracker frame),
    temp_c, and t_s where the source's timestamp is intact (series A; B's was
    damaged by a spreadsheet); the probe's point on the flange from the
    series' Trafo_TM_F_init.txt in the '# tool_mm:' line.  Returns the path."""
    import datetime

    folder = realdata_dir() / IPA_UR10
    src = folder / IPA_SERIES[series]
    rows = src.read_text(encoding="utf-8").splitlines()
    head = rows[0].split(";")
    col = {name: i for i, name in enumerate(head)}
    joints = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint"]
    clock = series == "A"
    t0 = None
    out = [f"# IPA UR10 series {series} of {src} (MIT; see its README), converted by tests/realdata.py",
           "# tool_mm: " + ", ".join(f"{v:.6g}" for v in ipa_ur10_tool_mm(series)),
           ",".join((["t_s"] if clock else []) + ["q1", "q2", "q3", "q4", "q5", "q6", "temp_c", "x", "y", "z"])]
    for line in rows[1:]:
        if not line.strip():
            continue
        c = line.split(";")
        q = np.rad2deg([_decimal_comma(c[col[j]]) for j in joints])
        m = [_decimal_comma(c[col[f"measurement_{a}"]]) for a in "xyz"]
        cells = []
        if clock:
            t = datetime.datetime.strptime(c[col["Timestamp"]].strip(), "%Y%m%d%H%M%S").timestamp()
            t0 = t if t0 is None else t0
            cells.append(f"{t - t0:.0f}")
        cells += [f"{v:.10g}" for v in q] + [f"{_decimal_comma(c[col['measurement_temperature']]):.6g}"]
        cells += [f"{v:.10g}" for v in m]
        out.append(",".join(cells))
    out_path = Path(out_path)
    out_path.write_text("\n".join(out) + "\n")
    return out_path


if __name__ == "__main__":  # python3 tests/realdata.py fanuc OUT.csv | ur10 A|B OUT.csv: in this project's format
    import sys

    args = sys.argv[1:]
    ok = (len(args) == 2 and args[0] == "fanuc") or (len(args) == 3 and args[0] == "ur10" and args[1] in IPA_SERIES)
    if not ok:
        sys.exit("usage: python3 tests/realdata.py fanuc OUT.csv | python3 tests/realdata.py ur10 A|B OUT.csv")
    reason = missing(FANUC if args[0] == "fanuc" else IPA_UR10)
    if reason:
        sys.exit(reason)
    if Path(args[-1]).exists():
        sys.exit(f"{args[-1]}: exists; not overwritten")
    out = fanuc_campaign_csv(args[-1]) if args[0] == "fanuc" else ipa_ur10_campaign_csv(args[1], args[-1])
    print(f"wrote {out}")
