"""``robstiff synth stiffness|payload|tracker OUT.csv``: virtual
measurement campaigns from the model (see identification/stiffness/synth.py); the
tracker's from Drake's plant of a perturbed arm (diagrams/tracker_world.py)."""

import sys

import numpy as np

from robstiff_drake.commands.options import parse_tool, parse_vector
from robstiff_drake.errors import InputError
from robstiff_drake.io import STDOUT, check_outputs, write_atomic
from robstiff_drake.model.effects import EFFECTS
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import info

DEFAULT_EFFECT_RMS_MM = 0.04


def _info(out):
    """Where the one-line summary goes: stderr when the CSV goes to stdout."""
    return sys.stderr if str(out) == STDOUT else sys.stdout


def parse_effects(items):
    """['lost_motion', 'drift=0.03'] -> {'lost_motion': 0.04, 'drift': 0.03} (RMS, mm)."""
    out = {}
    for item in items or []:
        name, _, size = item.partition("=")
        name = name.strip()
        if name not in EFFECTS:
            raise InputError(f"synth: unknown effect '{name}' (known: {', '.join(EFFECTS)})")
        try:
            rms = float(size) if size else DEFAULT_EFFECT_RMS_MM
        except ValueError:
            raise InputError(f"synth: --effect {item}: size '{size}' is not a number (RMS in mm)") from None
        if not 0 < rms < 10:
            raise InputError(f"synth: --effect {item}: RMS size must be in (0, 10) mm")
        out[name] = rms
    return out


def _positive(name, value, integer=False):
    if not value > 0 or (integer and int(value) != value):
        raise InputError(f"synth: {name} must be a positive {'integer' if integer else 'number'}, got {value}")


# What the first comment line of a file robstiff made says (synth's campaigns, plan-poses' plans; the docs'
# rounded examples of them start '# Synthetic: ...'): such a file may be written over; any other existing file
# may hold measurements.
MADE_BY_ROBSTIFF = ("made by robstiff-drake", "made by robstiff synth")


def check_not_measurements(out):
    """InputError when OUT.csv exists and is not a file robstiff made (its
    first line does not say so): a synthetic campaign written over a
    campaign measured on the robot would lose the measurements (before, it
    did, silently: 'robstiff synth stiffness fanuc.csv' over the FANUC
    campaign)."""
    from pathlib import Path

    path = Path(str(out))
    if str(out) == STDOUT or not path.is_file() or path.stat().st_size == 0:
        return
    with open(path, "rb") as f:
        head = f.read(4096).decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = head.splitlines()
    first = lines[0] if head.strip() else ""
    header = next((ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")), "")
    cells = {c.strip().lower() for c in header.replace(";", ",").replace("\t", ",").split(",")}
    if first.startswith("#") and (any(m in first for m in MADE_BY_ROBSTIFF) or first.startswith("# Synthetic")):
        if "measurement plan" not in first.lower() or not {"dx", "dy", "dz"} & cells:
            return
        raise InputError(f"{out}: a measurement plan with measured displacements added (its header has dx, dy, "
                         "dz); it is not written over: give another file name")
    raise InputError(f"{out}: exists and was not made by robstiff (its first line: {first[:60]!r}); it is not "
                     "written over, it may hold measurements: give another file name, or delete the file first")


def _write(out, text):
    if str(out) == STDOUT:
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        write_atomic(out, text)


def run_stiffness(*, out, n=120, loads_per_pose=4, force_N=300.0, noise_mm=0.01, seed=0, tool=None,
                  effects=None, stiffness=None, robot_yaml=None):
    check_outputs(inputs=[robot_yaml], files={"OUT.csv": out})
    check_not_measurements(out)
    robot = load_robot(robot_yaml)
    _positive("--n", n, True)
    _positive("--loads-per-pose", loads_per_pose, True)
    _positive("--force-N", force_N)
    if not noise_mm >= 0:
        raise InputError(f"synth: --noise-mm must be >= 0, got {noise_mm}")
    tool_m = robot.tool_point(parse_tool(tool), where="synth stiffness")
    k = None
    if stiffness is not None:
        k = np.array(parse_vector(stiffness, 6, "--stiffness"))
        if np.any(k <= 0):
            raise InputError("synth: --stiffness values must be > 0 (N*m/rad)")
    effects = parse_effects(effects)
    from robstiff_drake.identification.stiffness import synth  # scipy: after the checks of the arguments

    try:
        c = synth.stiffness_campaign(robot, n=n, loads_per_pose=loads_per_pose, force_N=force_N, noise_mm=noise_mm,
                                     seed=seed, tool_m=tool_m, effects=effects,
                                     true_stiffness_Nm_per_rad=k)
    except ValueError as e:
        raise InputError(f"synth: {e}") from None
    _write(out, synth.stiffness_csv(c, robot=robot, noise_mm=noise_mm, seed=seed, force_N=force_N,
                                          tool_m=tool_m))
    extra = "".join(f", {k_} RMS {raw:.4f} mm ({vis:.4f} mm beyond the six-spring model)"
                    for k_, (raw, vis) in c.effect_rms_mm.items())
    info(f"wrote {out}: {n} measurements at {len(set(c.pose))} poses{extra}", file=_info(out))
    return 0


def run_payload(*, out, n=15, mass_kg=None, com=None, noise_N=1.0, noise_Nm=0.1, seed=0, robot_yaml=None):
    check_outputs(inputs=[robot_yaml], files={"OUT.csv": out})
    check_not_measurements(out)
    robot = load_robot(robot_yaml)
    _positive("--n", n, True)
    if mass_kg is not None:
        _positive("--mass-kg", mass_kg)
    com_m = None if com is None else np.array(parse_vector(com, 3, "--com-mm")) / 1000.0
    from robstiff_drake.identification.stiffness import synth  # scipy: after the checks of the arguments

    c = synth.payload_campaign(robot, n=n, mass_kg=mass_kg, com_m=com_m, noise_N=noise_N, noise_Nm=noise_Nm,
                               seed=seed)
    _write(out, synth.payload_csv(c, noise_N=noise_N, noise_Nm=noise_Nm, seed=seed))
    info(f"wrote {out}: {n} configurations, payload {c.mass_kg:g} kg", file=_info(out))
    return 0


def run_tracker(*, out, n=300, noise_mm=0.03, seed=0, export=False, robot_yaml=None):
    """A laser-tracker campaign of the robot file's arm as Drake's plant of a
    perturbed copy measures it (diagrams/tracker_world.py: its joint offsets,
    link lengths and twists, stiffness, the tracker's place, drift and
    noise drawn from ``seed``)."""
    check_outputs(inputs=[robot_yaml], files={"OUT.csv": out})
    check_not_measurements(out)
    robot = load_robot(robot_yaml)
    from robstiff_drake.diagrams.tracker_world import make_tracker_campaign  # Drake: after the checks

    c = make_tracker_campaign(robot, seed, n=n, noise_mm=noise_mm, extra_columns=export)
    _write(out, c.csv_text)
    info(f"wrote {out}: {c.n} poses of a perturbed {robot.name} measured by a tracker (noise {noise_mm:g} mm); "
         f"planted: {', '.join(c.true['effects'])}; the target "
         + ", ".join(f"{v:.3f}" for v in c.true["tool_mm"]) + " mm on the flange (the file's guess in its "
         "'# tool_mm:' line)", file=_info(out))
    return 0
