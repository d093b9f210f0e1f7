"""diagnose-run's lost_motion cause on synthetic signals (no simulation):
its columns are the compensator's hysteretic law (each gear on the flank it
last pressed until its torque passes the friction the other way, the link
crossing the gap with its inertia), so play on a pass whose gear torque
changes sign is named with b near the truth, a play beyond the catalogue's
1 arcmin is named with a warning (not vetoed), and a face of noise names
nothing."""

from types import SimpleNamespace

import numpy as np
import pytest

from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.causes import (
    LOST_MOTION_CATALOGUE_RAD, LOST_MOTION_LIMIT_RAD, Envelope, Fit, candidates, trace,
)
from robstiff_drake.identification.runs.diagnosis import _beyond_catalogue
from robstiff_drake.identification.runs.signals import RunSignals, play_crossing_deviation
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.model.transmission import gap_friction_Nm

STIFFNESS_NM_PER_RAD = np.array([1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5])
FLOOR_MM = 0.003
CUTTER_MM = 75.0


def _signals():
    """A pass along y at 40 mm/s, 200 Hz, on which joint 2's gear torque runs
    from -30 to +40 N*m and back to -30 (past its friction, 18.15 N*m,
    both ways) and moves the tool vertically by -0.9 m/rad."""
    t = np.arange(0.0, 5.0, 0.005)
    n = t.size
    carried = np.zeros((n, 6))
    carried[:, 1] = 5.0 - 35.0 * np.cos(2 * np.pi * t / 5.0)
    Jz = np.zeros((n, 6))
    Jz[:, 1] = -0.9
    p = np.column_stack([np.full(n, 1.1), -0.1 + 0.04 * t, np.zeros(n)])
    zeros = np.zeros((n, 6))
    return RunSignals(t, zeros, zeros, zeros, -carried, zeros, zeros, carried[0].copy(), Jz, p,
                      1.0 / STIFFNESS_NM_PER_RAD, zeros, np.zeros(n), np.zeros(n), ServoParameters(60.0, 30.0, 1.0, 0.018), 0.05, 5.0,
                      twist_inertia_kgm2=np.tile([170.0, 256.0, 85.0, 4.3, 4.7, 0.32], (n, 1)))


def _trace(b2_rad, seed=3):
    sig = _signals()
    ys = np.arange(-0.05, 0.05, 5e-4) * 1e3
    scan = SimpleNamespace(x_mm=np.full(ys.size, 1100.0), y_mm=ys)
    env = Envelope(scan, sig, CUTTER_MM)
    b = np.array([0.0, b2_rad, 0.0, 0.0, 0.0, 0.0])
    friction = gap_friction_Nm(STIFFNESS_NM_PER_RAD)
    dev = play_crossing_deviation(sig.tau_static_Nm, sig.tau_touch_off_Nm, sig.tau_inertia_Nm, sig.tau_Nm, b,
                                  friction, sig.twist_inertia_kgm2, sig.t_s)
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, FLOOR_MM * 1e-3, env.covered.sum())
    y = env.surface(np.einsum("nj,nj->n", sig.Jz, dev)) + noise
    segs = ss.segments(scan.x_mm[env.covered], scan.y_mm[env.covered])
    ctx = {"segs": segs, "length_mm": ss.scan_length_mm(scan.x_mm, scan.y_mm, segs), "cutter_mm": CUTTER_MM}
    _, *cands = candidates(sig)  # the loop's column is zero here (no correction logged)
    empty = Fit([], [], np.zeros(0), float(y @ y), -y)
    rounds, final = trace(env, cands, y, FLOOR_MM * 1e-3, ctx, empty)
    return rounds, final, y


@pytest.mark.parametrize("b2_urad", [150.0, 600.0])
def test_play_is_named_with_its_size(b2_urad):
    rounds, final, y = _trace(b2_urad * 1e-6)
    assert np.sqrt(np.mean(y**2)) > 0.1e-3  # the play leaves a tenth of a millimetre or more on the face
    names = [c.name for c in final.causes]
    assert names == ["lost_motion"], rounds[0]
    fitted = final.theta[0]
    assert fitted == pytest.approx(b2_urad * 1e-6, rel=0.2)
    row = next(r for r in rounds[0] if r["name"] == "lost_motion")
    assert row["named"] and not row["at_bound"]
    warned = _beyond_catalogue({"lost_motion": {"b2": fitted}})
    assert bool(warned) == (fitted > LOST_MOTION_CATALOGUE_RAD)
    if warned:
        assert "beyond an RV gear's catalogued lost motion" in warned[0] and "worn gear" in warned[0]


def test_a_face_of_noise_names_nothing():
    rounds, final, _ = _trace(0.0)
    assert final.causes == [], [r for r in rounds[0] if r.get("named")]


def test_the_bound_is_the_plants_physical_limit():
    from robstiff_drake.diagrams.scenario_schema import MAX_PLAY_RAD

    assert LOST_MOTION_LIMIT_RAD == MAX_PLAY_RAD
    assert LOST_MOTION_LIMIT_RAD > 5 * LOST_MOTION_CATALOGUE_RAD
