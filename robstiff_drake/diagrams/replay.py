"""A 3D replay of a simulated cut, as one self-contained HTML file that
opens in a browser without a server (``robstiff simulate ... --replay
OUT.html``).

The closed loop's station builds its plant without a SceneGraph, so the
replay is built afterwards from the logged link angles: a separate
(continuous) MultibodyPlant with a SceneGraph and a MeshcatVisualizer,
holding one robot per run and a translucent one on the planned path.  Each
frame sets the robots' joint angles and publishes; Meshcat records the
frames into an animation, and its ``StaticHtml`` writes the scene, the
animation and the viewer's JavaScript into one file.

What is drawn (Drake's world frame = the robot's base frame, m):
  * each run's robot at q_plan + N (q - q_plan): q the simulated link angles,
    q_plan the joint angles of the planned path, N the magnification (chosen
    so that the largest tool-point deviation shows as about 150 mm, rounded
    down to 1, 2 or 5 times a power of ten), with its spindle;
  * the robot on the planned path (translucent grey);
  * the workpiece boxes (drawn WORKPIECE_DEPTH_M deep: the scenario gives
    only their tops);
  * the planned tool path (black) and each run's magnified tool path.
The page carries a caption with N and what each colour is.
"""

import logging
import re
from dataclasses import dataclass

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.description import make_urdf

TARGET_MAGNIFIED_M = 0.15  # the largest magnified tool-point deviation shown, about
WORKPIECE_DEPTH_M = 0.05  # drawn depth of the workpiece boxes (the scenario gives their tops only)
FRAMES_PER_SECOND = 30.0
MAX_FRAMES = 3000  # a longer run is recorded at a lower frame rate (file size)
CAPTION_ID = "robstiff-replay-caption"

# colours (r, g, b, a) of each run's robot and tool path, and of the planned ones
RUN_COLORS = {"uncompensated": (0.95, 0.45, 0.05, 1.0), "compensated": (0.10, 0.45, 0.85, 1.0)}
PLANNED_ROBOT_RGBA = (0.6, 0.6, 0.6, 0.25)
PLANNED_PATH_RGBA = (0.0, 0.0, 0.0, 1.0)
WORKPIECE_RGBA = (0.35, 0.55, 0.45, 0.5)  # translucent: the tool path runs inside the material
CAMERA_OFFSET_M = np.array([1.0, -1.8, 0.7])  # from the point it looks at: in front, to the side, above


def start_meshcat(port=None):
    """A Meshcat server on localhost (``port``, or the first free one from
    7000 on): the recording needs it.  InputError (one line) when it cannot
    start, so that a command can stop before its simulation."""
    from pydrake.geometry import Meshcat, MeshcatParams

    drake_log = logging.getLogger("drake")
    level = drake_log.level
    drake_log.setLevel(logging.WARNING)  # not its "listening at ..." line
    try:
        return Meshcat(MeshcatParams(host="localhost", port=port))
    except RuntimeError as e:
        raise InputError(f"--replay: Meshcat cannot start its server on localhost ({' '.join(str(e).split())}); "
                         "run without --replay") from None
    finally:
        drake_log.setLevel(level)


def check_replay_path(path):
    """The replay is an HTML file: refuse another suffix (InputError)."""
    if not str(path).lower().endswith((".html", ".htm")):
        raise InputError(f"--replay {path}: the replay is an HTML file; give a name ending in .html")


def nice_factor(x):
    """The largest of 1, 2, 5 times a power of ten that is <= x (and >= 1)."""
    if not np.isfinite(x) or x <= 1.0:
        return 1.0
    base = 10.0 ** np.floor(np.log10(x))
    return float(max(m * base for m in (1.0, 2.0, 5.0) if m * base <= x * (1 + 1e-12)))


@dataclass
class RunTrack:
    """One run's joint angles at the replay's frame times (rad, model angles)."""

    name: str
    q: np.ndarray  # (frames, 6) simulated link angles
    q_plan: np.ndarray  # (frames, 6) the planned path's joint angles


def tool_points(robot, tool_m, q):
    """Tool points (m, base frame) at link angles q (N, 6)."""
    T = kin.frames(robot.dh, q)[:, 6]
    return T[:, :3, 3] + T[:, :3, :3] @ tool_m


def tracks(results, times):
    """RunTrack per result, sampled at ``times`` (s)."""
    out = []
    for res in results:
        t, x = res.logs["state"]
        cell = res.cell
        q = np.column_stack([np.interp(times, t, x[:, j]) for j in range(6)])
        q_plan = np.column_stack([np.interp(times, cell.q_ref_times, cell.q_ref[:, j]) for j in range(6)])
        out.append(RunTrack("compensated" if res.compensation else "uncompensated", q, q_plan))
    return out


def magnification(robot, tool_m, runs):
    """N such that the largest tool-point deviation from the planned path,
    magnified, is about TARGET_MAGNIFIED_M; and that deviation (m)."""
    dev = max(float(np.max(np.linalg.norm(tool_points(robot, tool_m, r.q) - tool_points(robot, tool_m, r.q_plan),
                                          axis=1))) for r in runs)
    return (nice_factor(TARGET_MAGNIFIED_M / dev) if dev > 0 else 1.0), dev


def _urdf_with_color(robot, link_rgba, all_rgba=None):
    """The robot's URDF with its link colour (and, with ``all_rgba``, every
    colour, the spindle's too) replaced."""
    text = make_urdf(robot)
    rgba = " ".join(f"{v:g}" for v in link_rgba)
    text = re.sub(r'(<material name="link_color"><color rgba=")[^"]*', rf"\g<1>{rgba}", text)
    if all_rgba is not None:
        text = re.sub(r'(<color rgba=")[^"]*', r"\g<1>" + " ".join(f"{v:g}" for v in all_rgba), text)
    return text


def build_scene(meshcat, robot, names, fps=FRAMES_PER_SECOND):
    """A diagram with a continuous plant holding a robot per name in
    ``names`` and one on the planned path ('planned'), a SceneGraph and a
    MeshcatVisualizer.  Returns (diagram, plant, {name: model instance}, visualizer)."""
    from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    instances = {}
    for name in ("planned", *names):
        text = (_urdf_with_color(robot, PLANNED_ROBOT_RGBA, PLANNED_ROBOT_RGBA) if name == "planned"
                else _urdf_with_color(robot, RUN_COLORS[name]))
        (inst,) = Parser(plant, model_name_prefix=name).AddModelsFromString(text, "urdf")
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(robot.links[0].name, inst))
        instances[name] = inst
    plant.Finalize()
    params = MeshcatVisualizerParams()
    params.prefix = "robots"
    params.publish_period = 1.0 / fps  # the recording's frame rate
    vis = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
    return builder.Build(), plant, instances, vis


def draw_cell(meshcat, sc, workpiece, planned_path_m, run_paths_m):
    """The workpiece boxes and the tool paths (static objects)."""
    from pydrake.geometry import Box, Rgba
    from pydrake.math import RigidTransform

    for i, ((x0, x1), (y0, y1), top) in enumerate(zip(workpiece.x_m, workpiece.y_m, workpiece.top_m)):
        path = f"/cell/workpiece/box_{i}"
        meshcat.SetObject(path, Box(x1 - x0, y1 - y0, WORKPIECE_DEPTH_M), Rgba(*WORKPIECE_RGBA))
        meshcat.SetTransform(path, RigidTransform([(x0 + x1) / 2, (y0 + y1) / 2, top - WORKPIECE_DEPTH_M / 2]))
    meshcat.SetLine("/cell/tool_path/planned", np.asfortranarray(planned_path_m.T), 3.0, Rgba(*PLANNED_PATH_RGBA))
    for name, p in run_paths_m.items():
        meshcat.SetLine(f"/cell/tool_path/{name}_magnified", np.asfortranarray(p.T), 2.0, Rgba(*RUN_COLORS[name]))


def caption_html(sc, robot, factor, deviation_m, names, t_end_s):
    """The page's caption: what is shown and the magnification."""
    runs = ", ".join(f"{n}: {_color_name(n)}" for n in names)
    return (f'<div id="{CAPTION_ID}" style="position:fixed;left:8px;bottom:8px;max-width:60vw;z-index:10;'
            'background:rgba(255,255,255,0.85);padding:6px 10px;font:13px sans-serif;border-radius:4px">'
            f'<b>{_html(sc.name)}</b> ({_html(robot.manufacturer)} {_html(robot.model)}), {t_end_s:.1f} s simulated. '
            f'<b>Deflection magnified <span id="robstiff-magnification">{factor:g}</span>&times;</b>: each robot is '
            f'drawn at planned + {factor:g} &times; (simulated &minus; planned) joint angles, so its tool point '
            f'leaves the planned path by {factor:g} times its real deviation (largest real deviation '
            f'{deviation_m * 1e3:.3f} mm: the deflection under the cut and the servo\'s lag). Robots: {runs}; '
            'translucent grey: on the planned path. Lines: black, the planned tool path; coloured, each run\'s '
            f'magnified tool path. Workpiece boxes drawn {WORKPIECE_DEPTH_M * 1e3:.0f} mm deep. Controls (top '
            'right): Animations to replay, the scene tree to hide a robot.</div>')


def _color_name(name):
    return {"uncompensated": "orange", "compensated": "blue"}[name]


def _html(text):
    return str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def replay_html(meshcat, sc, results, robot, *, fps=FRAMES_PER_SECOND):
    """Record the runs into ``meshcat`` and return (html text, info dict:
    magnification, deviation_m, frames, fps)."""
    from pydrake.geometry import MeshcatAnimation

    cell = results[0].cell
    tool_m = cell.tool_m
    t_end = max(float(r.logs["state"][0][-1]) for r in results)
    fps = min(fps, MAX_FRAMES / max(t_end, 1e-9))
    times = np.arange(0.0, t_end + 0.5 / fps, 1.0 / fps)
    runs = tracks(results, times)
    factor, dev = magnification(robot, tool_m, runs)
    shown = {r.name: r.q_plan + factor * (r.q - r.q_plan) for r in runs}
    q_plan = runs[0].q_plan

    diagram, plant, instances, vis = build_scene(meshcat, robot, [r.name for r in runs], fps)
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    vis_context = vis.GetMyContextFromRoot(context)
    path_t = np.linspace(0.0, cell.path.duration_s, 400)
    draw_cell(meshcat, sc, cell.workpiece, cell.path.positions(path_t),
              {name: tool_points(robot, tool_m, q) for name, q in shown.items()})
    meshcat.SetCameraPose(_target(cell) + CAMERA_OFFSET_M, _target(cell))

    def show(k):
        plant.SetPositions(plant_context, instances["planned"], q_plan[k])
        for name, q in shown.items():
            plant.SetPositions(plant_context, instances[name], q[k])

    vis.StartRecording(set_transforms_while_recording=False)
    for k, t in enumerate(times):
        context.SetTime(float(t))
        show(k)
        vis.ForcedPublish(vis_context)
    vis.StopRecording()
    animation = vis.get_mutable_recording()
    animation.set_loop_mode(MeshcatAnimation.LoopMode.kLoopRepeat)
    animation.set_repetitions(1000000)
    vis.PublishRecording()
    context.SetTime(0.0)
    show(0)
    vis.ForcedPublish(vis_context)  # the scene as it opens, before the animation plays
    html = meshcat.StaticHtml()
    caption = caption_html(sc, robot, factor, dev, list(shown), t_end)
    html = html.replace("<body>", "<body>\n" + caption, 1)
    return html, {"magnification": factor, "max_deviation_mm": dev * 1e3, "frames": len(times),
                  "frames_per_second": fps}


def _target(cell):
    """Where the camera looks (m): the middle of the workpiece's top."""
    w = cell.workpiece
    return np.array([w.x_m.mean(), w.y_m.mean(), float(np.max(w.top_m))])
