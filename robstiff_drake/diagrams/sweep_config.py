"""A scenario set up for one combination of a sweep (controller period,
delay steps, force-filter cutoff, mode; optionally the plant step), checked
like any scenario.  Its own module so that the sweep and the loop model's
prediction of it share it without importing each other."""

import copy


def configure(sc, combo, plant_step_ms=None):
    sc = copy.deepcopy(sc)
    sc.controller.period_ms = combo["period_ms"]
    sc.controller.delay_steps = combo["delay_steps"]
    sc.controller.filter.kind = "lowpass"
    sc.controller.filter.cutoff_hz = combo["cutoff_hz"]
    sc.controller.mode = combo["mode"]
    if plant_step_ms:
        sc.plant_config.time_step = plant_step_ms / 1e3
    from robstiff_drake.diagrams.scenario import check_scenario

    check_scenario(sc)
    return sc
