"""The IRB6400 as a Drake MultibodyPlant, loaded from ``models/`` by Drake's
Parser (URDF + package.xml) and welded to the world.

The plant's joint positions are the controller angles q (rad): the home
offsets of Table 1 are in the URDF's joint origins.
"""

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from robstiff_drake.model.description import PACKAGE_NAME
from robstiff_drake.paths import IRB6400_PACKAGE_XML

IRB6400_URL = f"package://{PACKAGE_NAME}/urdf/irb6400.urdf"
JOINT_NAMES = tuple(f"joint_{i}" for i in range(1, 7))


def add_irb6400(plant, *, X_WBase=None):
    """Parse the IRB6400 into ``plant`` and weld its base to the world.
    Returns the model instance."""
    parser = Parser(plant)
    parser.package_map().AddPackageXml(str(IRB6400_PACKAGE_XML))
    (instance,) = parser.AddModelsFromUrl(IRB6400_URL)
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName("base", instance),
        X_WBase if X_WBase is not None else RigidTransform(),
    )
    return instance


def make_irb6400_plant(time_step=0.0, *, with_scene_graph=False):
    """A finalized plant of the IRB6400 (continuous when ``time_step`` is 0).

    Returns (plant, instance), or (diagram, plant, instance) with a
    SceneGraph when ``with_scene_graph`` is true."""
    if with_scene_graph:
        builder = DiagramBuilder()
        plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=time_step)
        instance = add_irb6400(plant)
        plant.Finalize()
        return builder.Build(), plant, instance
    plant = MultibodyPlant(time_step=time_step)
    instance = add_irb6400(plant)
    plant.Finalize()
    return plant, instance


def tool_position_and_jacobian(plant, context, q_rad, tool_m=None):
    """Drake's answer for the tool point on the flange: its position (m) in
    the world and the 6x6 Jacobian in the project's convention (linear rows
    first), from MultibodyPlant.CalcJacobianSpatialVelocity."""
    plant.SetPositions(context, np.asarray(q_rad, dtype=float))
    flange = plant.GetFrameByName("flange")
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    p = plant.CalcPointsPositions(context, flange, tool.reshape(3, 1), plant.world_frame())[:, 0]
    Jw = plant.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kQDot, flange, tool, plant.world_frame(), plant.world_frame()
    )
    return p, np.vstack([Jw[3:], Jw[:3]])
