"""The error budget's split of the error field (model/budget_fields.py) on
synthetic fields whose truth is known by construction (plain numpy, no
simulation), against the one-at-a-time split of the RMS it replaces; and
the budget's removals (diagrams/budget.without) changing only what their
labels say."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from robstiff_drake.model.budget_fields import field_shares, one_at_a_time, rms

ROOT = Path(__file__).resolve().parents[1]


def additive_fields(rng, n, points=4000, size_mm=0.01):
    """n uncorrelated source fields of equal size, a small floor, their sum."""
    x = np.linspace(0.0, 1.0, points)
    sources = {f"s{i}": size_mm * rng.standard_normal(points) for i in range(n)}
    floor = 0.001 * np.sin(2 * np.pi * 3 * x)
    full = floor + sum(sources.values())
    return full, {k: full - v for k, v in sources.items()}, floor, sources


@pytest.mark.parametrize("n", [2, 4, 10])
def test_additive_uncorrelated_sources_add_up_and_leave_no_interaction(n):
    """The field split adds to 1 with no interaction; the one-at-a-time RMS
    split of the same additive fields calls 29-49 % of them interaction
    (sqrt(n) s against n (sqrt(n) - sqrt(n - 1)) s): this fails on the old
    method."""
    rng = np.random.default_rng(29 + n)
    full, without, floor, sources = additive_fields(rng, n)
    f = field_shares(full, without, floor)
    assert abs(f["floor"] + sum(f["shares"].values()) - 1.0) < 1e-12
    assert abs(f["interaction"]) < 1e-12
    assert abs(f["floor_mm"] + sum(f["shares_mm"].values()) + f["interaction_mm"] - f["rms_mm"]) < 1e-12
    for k in sources:  # equal uncorrelated sources: about 1/n each (the floor is ~1 % of the mean square)
        assert abs(f["shares"][k] - 1.0 / n) < 0.15 / n
    m = f["mean_mm"]
    assert abs(m["floor"] + sum(m[k] for k in sources) - m["total"]) < 1e-12 and abs(m["interaction"]) < 1e-12
    contributions, interaction = one_at_a_time(rms(full), {k: rms(v) for k, v in without.items()}, rms(floor))
    frac = interaction / (rms(full) - rms(floor))
    assert frac > 0.25  # the old method's artefact: quadrature, not physics
    assert f["interaction"] < 0.01 * frac


def test_correlated_and_cancelling_sources_still_add_up():
    """Sources that correlate or partly cancel (one's field against
    another's) still add to 1 when they add; a cancelling source's share is
    negative."""
    rng = np.random.default_rng(7)
    a = 0.01 * rng.standard_normal(2000)
    b = 0.5 * a + 0.004 * rng.standard_normal(2000)
    c = -0.3 * a
    floor = np.full(2000, 0.002)
    full = floor + a + b + c
    f = field_shares(full, {"a": full - a, "b": full - b, "c": full - c}, floor)
    assert abs(f["interaction"]) < 1e-12
    assert f["shares"]["c"] < 0 < f["shares"]["b"] < f["shares"]["a"]


def test_a_true_interaction_is_what_is_left():
    """With a product term (two sources that matter only together), the
    interaction is that term's projection on the cut's field."""
    rng = np.random.default_rng(11)
    a = 0.01 * rng.standard_normal(3000)
    b = 0.01 * rng.standard_normal(3000)
    cross = 40.0 * a * b  # present only when both are
    floor = np.zeros(3000)
    full = a + b + cross
    f = field_shares(full, {"a": b, "b": a}, floor)  # without a: b alone (and no cross term)
    # e_a = full - b = a + cross, e_b = b + cross: the cross term is counted twice, the interaction takes it back
    expected = -float(cross @ full) / float(full @ full)
    assert abs(f["interaction"] - expected) < 1e-12 and abs(expected) > 0.05


def test_fields_on_different_scan_points_are_refused():
    with pytest.raises(ValueError, match="not on the same scan points"):
        field_shares(np.zeros(10) + 1.0, {"a": np.zeros(9)}, np.zeros(10))


def test_the_filter_noise_factor_is_the_filtered_white_noise():
    """model/filters.noise_std_factor against white noise filtered by scipy
    and against a second-order Butterworth's noise bandwidth,
    fc (pi / 4) / sin(pi / 4): variance gain 2 ENBW / fs."""
    from robstiff_drake.model.filters import noise_std_factor

    b, a = signal.butter(2, 2.0, btype="low", fs=1000.0)
    factor = noise_std_factor(b, a)
    enbw_hz = 2.0 * (np.pi / 4) / np.sin(np.pi / 4)
    assert abs(factor - np.sqrt(2 * enbw_hz / 1000.0)) < 0.002
    w = np.random.default_rng(3).standard_normal(400_000)
    assert abs(np.std(signal.lfilter(b, a, w)[5000:]) / factor - 1.0) < 0.05


# what each removal may change in the scenario (dotted fields; "_x" the scenario's private settings)
ALLOWED = {
    "stiffness model error": {"model.joint_stiffness_Nm_per_rad", "model.identified_json"},
    "payload and bias error": {"model.payload_yaml"},
    "cutting-coefficient error": {"model.force_model_scale"},
    "force filter lag": {"controller.filter.kind", "sensor.noise_N", "sensor.noise_Nm", "_lag_free_cutting_sensor"},
    "sensor noise": {"sensor.noise_N", "sensor.noise_Nm"},
    "servo and interpolator lag": {"servo.interpolator_delay_ms", "servo.position_gain_per_s",
                                   "servo.velocity_bandwidth_hz"},
    "sampling period and delay": {"controller.delay_steps", "controller.period_ms", "servo.interpolator_period_ms",
                                  "sensor.rate_hz", "plant_config.time_step"},
    "lost motion": {"plant.lost_motion_rad", "model.lost_motion_rad"},
    "arm dynamic response": {"_payload_calibration_override", "plant_config.time_step"},
    "kinematic error": {"_controller_robot"},
    "scan noise": {"scan.noise_mm"},
}
BOOKKEEPING = {"_user_model_pinned", "_reidentify_servo"}  # every budget run's (the model it keeps, not a removal)


def flat(sc):
    out = {}

    def walk(prefix, v):
        if isinstance(v, dict):
            for k, x in v.items():
                walk(f"{prefix}.{k}" if prefix else str(k), x)
        elif hasattr(v, "__fields__"):  # Drake's configs (the plant's, the simulator's)
            walk(prefix, {f.name: getattr(v, f.name) for f in v.__fields__})
        else:
            out[prefix] = v

    walk("", dataclasses.asdict(sc))
    out.update({k: v for k, v in vars(sc).items() if k.startswith("_")})
    return out


@pytest.mark.parametrize("source", sorted(ALLOWED))
def test_each_removal_changes_only_its_own_source(robot, source):
    """``without`` with one source removed changes only that source's
    settings; a plant-step change is printed (ALSO_CHANGES); "force filter
    lag" keeps the noise filtering's size (the lag-free sensor's noise is
    the filtered noise's, white noise through the scenario's own filter)."""
    from robstiff_drake.diagrams import budget
    from robstiff_drake.diagrams.scenario import load_scenario

    sc = load_scenario(ROOT / "tests" / "data" / "short_block.yaml")
    sc.plant.lost_motion_rad = [2.9e-4] * 6
    sc.model.lost_motion_rad = [2.9e-4] * 6
    sc.scan.noise_mm = 0.003
    s, rob, gravity = budget.without(sc, robot, frozenset([source]), None)
    before, after = flat(sc), flat(s)
    changed = {k for k in set(before) | set(after) if k not in BOOKKEEPING and
               (k not in before or k not in after or not np.array_equal(np.asarray(before[k], dtype=object),
                                                                         np.asarray(after[k], dtype=object)))}
    assert changed <= ALLOWED[source], changed - ALLOWED[source]
    if "plant_config.time_step" in changed:
        assert source in budget.ALSO_CHANGES
    assert (rob is robot and gravity == 1.0) == (source != "arm dynamic response")
    if source == "force filter lag":
        b, a = signal.butter(2, sc.controller.filter.cutoff_hz, btype="low", fs=sc.sensor.rate_hz)
        w = np.random.default_rng(5).standard_normal(200_000)
        filtered_std = np.std(signal.lfilter(b, a, w)[5000:])
        assert abs(s.sensor.noise_N / sc.sensor.noise_N / filtered_std - 1.0) < 0.05
        assert abs(s.sensor.noise_Nm / sc.sensor.noise_Nm / filtered_std - 1.0) < 0.05
