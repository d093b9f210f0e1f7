"""Helpers of the tests that drive the bare compliant arm
(diagrams/station.add_compliant_arm) without the milling station."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce_
from pydrake.systems.primitives import ConstantValueSource


def add_constant_tool_force(builder, plant, robot, force_N):
    """A constant force (N, base frame) on the spindle at the robot's tool
    point, into the plant's applied spatial force port."""
    f = ExternallyAppliedSpatialForce_[float]()
    f.body_index = plant.GetBodyByName("spindle").index()
    f.p_BoBq_B = robot.payload.tool_point_m
    f.F_Bq_W = SpatialForce(np.zeros(3), np.asarray(force_N, dtype=float))
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make([f])))
    builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())
