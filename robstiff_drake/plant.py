"""A robot as a Drake MultibodyPlant, parsed from the URDF that
model/description.py generates from its robot file, welded to the world.

The URDF is written into a cache folder (never into the installed package):
``$ROBSTIFF_CACHE_DIR``, else ``$XDG_CACHE_HOME/robstiff-drake``, else
``~/.cache/robstiff-drake``; its name carries a hash of its text, and before
it is parsed it is compared with the text generated from the robot file
again (a stale or edited copy is rewritten).  After parsing, the plant's
flange is checked against the numpy kinematics (``check_plant_matches``).

The plant's joint positions are the model's joint angles q (rad): the home
offsets are in the URDF's joint origins.
"""

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from robstiff_drake.errors import InputError
from robstiff_drake.io import write_atomic
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.description import make_urdf

JOINT_NAMES = tuple(f"joint_{i}" for i in range(1, 7))
CACHE_ENV = "ROBSTIFF_CACHE_DIR"
# How far Drake's flange may be from the numpy chain's (m) before a run is refused
PLANT_CHECK_TOL_M = 1e-9


def cache_dir():
    """The folder for generated URDFs (created when missing)."""
    if os.environ.get(CACHE_ENV):
        base = Path(os.environ[CACHE_ENV])
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg) if xdg else Path.home() / ".cache") / "robstiff-drake"
    for folder in (base, Path(tempfile.gettempdir()) / f"robstiff-drake-{os.getuid()}"):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            if os.access(folder, os.W_OK | os.X_OK):
                return folder
        except OSError:
            continue
    raise InputError(f"cannot write the robot description cache: neither {base} nor the temporary folder is "
                     f"writable (set {CACHE_ENV} to a writable folder)")


def code_digest(module_names):
    """A digest (hex) of the source of the modules named (a cached file
    made by other code is stale)."""
    import importlib
    import inspect

    h = hashlib.sha256()
    for name in module_names:
        try:
            h.update(inspect.getsource(importlib.import_module(name)).encode())
        except (OSError, TypeError, ImportError):
            h.update(name.encode())
    return h.hexdigest()


def robot_urdf(robot):
    """The URDF file of ``robot`` in the cache, (re)written when missing or
    different from what its robot file gives now.  Returns its path."""
    text = make_urdf(robot)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = cache_dir() / f"{robot.name}-{digest}.urdf"
    try:
        current = path.read_text() if path.exists() else None
    except (OSError, UnicodeDecodeError):
        current = None
    if current != text:
        write_atomic(path, text)
    return path


def _default(robot):
    if robot is None:
        from robstiff_drake.model.robot import load_robot

        robot = load_robot()
    return robot


def add_robot(plant, robot=None, *, X_WBase=None):
    """Parse ``robot`` (a RobotModel; default: the IRB6400) into ``plant``
    and weld its base to the world.  Returns the model instance."""
    robot = _default(robot)
    (instance,) = Parser(plant).AddModels(str(robot_urdf(robot)))
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName(robot.links[0].name, instance),
        X_WBase if X_WBase is not None else RigidTransform(),
    )
    return instance


add_irb6400 = add_robot  # the name before the robot library


def make_robot_plant(robot=None, time_step=0.0, *, with_scene_graph=False):
    """A finalized plant of ``robot`` (continuous when ``time_step`` is 0).

    Returns (plant, instance), or (diagram, plant, instance) with a
    SceneGraph when ``with_scene_graph`` is true."""
    robot = _default(robot)
    if with_scene_graph:
        builder = DiagramBuilder()
        plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=time_step)
        instance = add_robot(plant, robot)
        plant.Finalize()
        return builder.Build(), plant, instance
    plant = MultibodyPlant(time_step=time_step)
    instance = add_robot(plant, robot)
    plant.Finalize()
    return plant, instance


def make_irb6400_plant(time_step=0.0, *, with_scene_graph=False):
    """The default robot's plant (see make_robot_plant)."""
    return make_robot_plant(None, time_step, with_scene_graph=with_scene_graph)


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


def check_plant_matches(plant, robot, context=None):
    """Refuse (InputError) a plant whose flange is not where the robot file's
    kinematics put it, at three fixed configurations inside the working
    ranges, or whose mass differs from the file's: the URDF and its YAML
    must describe the same robot before a run."""
    ctx = context or plant.CreateDefaultContext()
    lo, hi = robot.q_lower_rad, robot.q_upper_rad
    worst = 0.0
    for f in (0.3, 0.5, 0.7):
        q = robot.joint_map.to_model(lo + f * (hi - lo))
        p, _ = tool_position_and_jacobian(plant, ctx, q)
        worst = max(worst, float(np.max(np.abs(p - kin.tool_position(robot.dh, q)))))
    mass = sum(plant.get_body(i).default_mass() for i in plant.GetBodyIndices(plant.GetModelInstanceByName(robot.name)))
    want = robot.total_mass_kg + robot.payload.mass_kg
    if worst > PLANT_CHECK_TOL_M or abs(mass - want) > 1e-9 * want:
        raise InputError(f"the Drake model of {robot.name} does not match its robot file {robot.source}: flange off "
                         f"by {worst * 1e3:.3g} mm, mass {mass:.6g} kg instead of {want:.6g} kg (stale URDF in "
                         f"{cache_dir()}? delete it)")
