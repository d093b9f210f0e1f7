"""How many calls from Python into pydrake's bindings the block pass's
Python updates make (issue 32: each costs about 3.5 k instructions of
binding work, benchmarks/instruction_counts.py).  The compensator tick
holds its state in one group that its update reads and writes in place,
and the milling force holds its feed, travel and history in one group the
same way (systems/compensator_tick.py, systems/milling_force.py).  Counted
with sys.setprofile, one update at a time, with C++ sources feeding the
inputs so that no other Python code runs.  The counts are exact: they do
not depend on the machine or its load."""

import sys

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from robstiff_drake.model import jit
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.milling_force import MillingForceSource

T = 0.004
Q = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])


def pydrake_calls(run):
    """The calls of builtin functions bound by pydrake made from Python
    while ``run()`` runs (the simulator's AdvanceTo itself left out)."""
    calls = []

    def hook(frame, event, arg):
        if event == "c_call" and "pydrake" in (getattr(arg, "__module__", None) or ""):  # (pybind11 names the module)
            if arg.__name__ != "AdvanceTo":
                calls.append(arg.__name__)

    sys.setprofile(hook)
    try:
        run()
    finally:
        sys.setprofile(None)
    return calls


def test_the_compensator_ticks_update_reads_and_writes_its_state_once(robot):
    """The tick carrying the guard, with its deflection model: one call for
    the state, one read of each input (the raw and the filtered wrench, the
    joint angles).  Before the state was one group: 15 (the held values
    taken, 3 groups read from them, 6 written, 2 of the guard's groups, 3
    inputs; main's tree, 2026-12-07)."""
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    b = DiagramBuilder()
    tick = b.AddSystem(CompensatorTick(
        period_s=T, calibration=PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0]), kinematics=kin,
        deflection=DeflectionModel(kin, tool), saturation_rad=2e-4, delay_steps=1, rate_limit_rad_per_s=0.05,
        guard=(1.0 / T, 500.0)))
    for port, value in (("raw_wrench", [100.0, -50.0, 400.0, 3.0, -2.0, 1.0]),
                        ("wrench", [90.0, -40.0, 410.0, 3.0, -2.0, 1.0]), ("q", Q)):
        b.Connect(b.AddSystem(ConstantVectorSource(np.asarray(value))).get_output_port(), tick.GetInputPort(port))
    sim = Simulator(b.Build())
    sim.AdvanceTo(2.5 * T)  # (the kernels loaded, the first updates done)
    calls = pydrake_calls(lambda: sim.AdvanceTo(3.5 * T))  # one update
    assert sorted(calls) == ["Eval"] * 3 + ["get_mutable_value"], calls


def test_the_averaged_milling_forces_update_reads_and_writes_its_progress_once(robot):
    """The averaged milling force's compiled update: the state written in
    place (the held wrench apart, and the spatial force's abstract state),
    its input and the time: 7 calls counted here (the SpatialForce made and
    set are not calls of bound functions).  Before: 11 (the progress and the
    history read and written as two groups; main's tree, 2026-12-07)."""
    if not jit.available():
        pytest.skip("numba is not installed: the update runs its reference, which this does not count")
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    _, p = kin.flange_rotation_and_tool_point(Q)
    law = PlantCuttingLaw(MillingForceModel(Cutter(0.075, 6, 3600), CuttingCoefficients(631, 99, 273, 13, 10, 2.8),
                                            0.02), PlantCuttingPhysics.linear())
    src = MillingForceSource(force_model=law, workpiece=Workpiece.from_boxes(
        [[p[0] - 0.05, p[0] + 0.1, p[1] - 0.02, p[1] + 0.03, p[2] + 0.003]]),
        path=PlannedPath([p - [0.1, 0, 0], p + [0.1, 0, 0]], 0.02), kinematics=kin, tool_point_m=tool, period_s=T,
        spindle_body_index=BodyIndex(7))
    b = DiagramBuilder()
    b.AddSystem(src)
    b.Connect(b.AddSystem(ConstantVectorSource(Q)).get_output_port(), src.get_input_port())
    sim = Simulator(b.Build())
    sim.AdvanceTo(2.5 * T)  # (the first update searches the whole path; the later ones are the compiled kind)
    calls = pydrake_calls(lambda: sim.AdvanceTo(3.5 * T))
    assert len(calls) == 7, calls
