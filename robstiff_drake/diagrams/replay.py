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
  * the planned tool path (black) and each run's magnified tool path, as
    tubes (a WebGL line is one pixel wide whatever its width says).
Where the robots coincide (the base, the links near it) their surfaces
would lie in one another and flicker (z-fighting): each is drawn a few
millimetres larger than the one inside it (ROBOT_INFLATE_M), the
compensated robot outside the uncompensated one, the planned robot's
translucent shell outside both.  The camera frames the robots over the
whole cut, the workpiece and the paths (``camera_pose``).  The page says N
in a title line and a caption with what each colour is.
"""

import logging
import re
from dataclasses import dataclass

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.description import make_urdf
from robstiff_drake.paths import replay_name_problem

TARGET_MAGNIFIED_M = 0.15  # the largest magnified tool-point deviation shown, about
WORKPIECE_DEPTH_M = 0.05  # drawn depth of the workpiece boxes (the scenario gives their tops only)
FRAMES_PER_SECOND = 30.0
MAX_FRAMES = 3000  # a longer run is recorded at a lower frame rate (file size)
CAPTION_ID = "robstiff-replay-caption"

# colours (r, g, b, a) of each run's robot and tool path, and of the planned ones
RUN_COLORS = {"uncompensated": (0.95, 0.45, 0.05, 1.0), "compensated": (0.10, 0.45, 0.85, 1.0)}
PLANNED_ROBOT_RGBA = (0.6, 0.6, 0.6, 0.25)
PLANNED_PATH_RGBA = (0.0, 0.0, 0.0, 1.0)
WORKPIECE_RGBA = (0.2, 0.65, 0.35, 0.6)  # translucent: the tool path runs inside the material
# the camera looks from beside the arm (-y), a little in front (+x) and above: the arm's plane (x-z) and the
# path's vertical deviations in profile
CAMERA_DIRECTION = np.array([0.35, -1.0, 0.2])
CAMERA_FOV_DEG = 75.0  # Meshcat's camera (three.js PerspectiveCamera), vertical field of view
FRAMING_MARGIN = 0.08  # share of the field of view left free around the framed points
# how much larger each robot is drawn than the one inside it (m): no coinciding surfaces
ROBOT_INFLATE_M = {"uncompensated": 0.0, "compensated": 0.004, "planned": 0.008}
PATH_TUBE_RADIUS_M = {"planned": 0.006, "run": 0.006}
TITLE_ID = "robstiff-replay-title"
SPINDLE_ALPHA = 0.35  # the spindles are drawn translucent: the tool path runs under them


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
    problem = replay_name_problem(path)
    if problem:
        raise InputError(problem)


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


def _inflated(text, inflate_m):
    """URDF text with every box and cylinder ``inflate_m`` larger on each side."""
    if not inflate_m:
        return text

    def box(m):
        return '<box size="' + " ".join(f"{float(v) + 2 * inflate_m:.9g}" for v in m.group(1).split()) + '"'

    def cylinder(m):
        return f'<cylinder radius="{float(m.group(1)) + inflate_m:.9g}" length="{float(m.group(2)) + 2 * inflate_m:.9g}"'

    text = re.sub(r'<box size="([^"]*)"', box, text)
    return re.sub(r'<cylinder radius="([^"]*)" length="([^"]*)"', cylinder, text)


def _urdf_with_color(robot, link_rgba, all_rgba=None, inflate_m=0.0):
    """The robot's URDF with its link colour (and, with ``all_rgba``, every
    colour, the spindle's too) replaced, its shapes ``inflate_m`` larger."""
    text = _inflated(make_urdf(robot), inflate_m)
    rgba = " ".join(f"{v:g}" for v in link_rgba)
    text = re.sub(r'(<material name="link_color"><color rgba=")[^"]*', rf"\g<1>{rgba}", text)
    # the spindle sits on the tool path: see the path and the workpiece through it
    text = re.sub(r'(<material name="steel"><color rgba=")([^"]*)', lambda m: m.group(1) + " ".join(
        m.group(2).split()[:3] + [f"{SPINDLE_ALPHA:g}"]), text)
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
        text = (_urdf_with_color(robot, PLANNED_ROBOT_RGBA, PLANNED_ROBOT_RGBA, ROBOT_INFLATE_M[name])
                if name == "planned" else _urdf_with_color(robot, RUN_COLORS[name], inflate_m=ROBOT_INFLATE_M[name]))
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
    draw_tube(meshcat, "/cell/tool_path/planned", planned_path_m, PATH_TUBE_RADIUS_M["planned"], PLANNED_PATH_RGBA)
    for name, p in run_paths_m.items():
        draw_tube(meshcat, f"/cell/tool_path/{name}_magnified", p, PATH_TUBE_RADIUS_M["run"], RUN_COLORS[name])


def tube_mesh(points_m, radius_m, sides=8):
    """(vertices (3, N*sides), faces (3, M)) of a tube of ``radius_m`` along
    the polyline ``points_m`` (N, 3); repeated points are dropped."""
    p = np.asarray(points_m, dtype=float)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9]
    p = p[keep]
    if len(p) < 2:
        p = np.vstack([p[:1], p[:1] + [1e-6, 0.0, 0.0]])
    tangent = np.gradient(p, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    ref = np.where(np.abs(tangent[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(tangent, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(tangent, u)
    angles = 2 * np.pi * np.arange(sides) / sides
    ring = (np.cos(angles)[None, :, None] * u[:, None, :] + np.sin(angles)[None, :, None] * v[:, None, :])
    vertices = (p[:, None, :] + radius_m * ring).reshape(-1, 3)
    faces = []
    for i in range(len(p) - 1):
        for k in range(sides):
            a, b = i * sides + k, i * sides + (k + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, b, d), (a, d, c)]
    return np.asfortranarray(vertices.T), np.asfortranarray(np.array(faces, dtype=np.int32).T)


def draw_tube(meshcat, path, points_m, radius_m, rgba):
    from pydrake.geometry import Rgba

    vertices, faces = tube_mesh(points_m, radius_m)
    meshcat.SetTriangleMesh(path, vertices, faces, Rgba(*rgba))


def drawn_points(plant, context, instances, q_by_name, frames=24):
    """Corners (m, world) of the bounding boxes of every illustration shape
    (boxes, cylinders) of the robots, at ``frames`` instants of the cut
    (``q_by_name``: {instance name: (frames, 6) joint angles})."""
    from pydrake.geometry import Box, Cylinder, Role

    plant_context = plant.GetMyMutableContextFromRoot(context)
    query = plant.get_geometry_query_input_port()
    inspector = query.Eval(plant_context).inspector()
    shapes = []
    for gid in inspector.GetAllGeometryIds():
        if inspector.GetProperties(gid, Role.kIllustration) is None:
            continue
        shape = inspector.GetShape(gid)
        if isinstance(shape, Box):
            half = np.array([shape.width(), shape.depth(), shape.height()]) / 2
        elif isinstance(shape, Cylinder):
            half = np.array([shape.radius(), shape.radius(), shape.length() / 2])
        else:
            continue
        shapes.append((gid, half))
    cube = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    n = len(next(iter(q_by_name.values())))
    pts = []
    for k in np.unique(np.linspace(0, n - 1, frames).astype(int)):
        for name, q in q_by_name.items():
            plant.SetPositions(plant_context, instances[name], q[k])
        q_obj = query.Eval(plant_context)
        for gid, half in shapes:
            X = q_obj.GetPoseInWorld(gid)
            pts.append((X.rotation().matrix() @ (cube * half).T).T + X.translation())
    return np.vstack(pts)


def camera_pose(points_m, aspect=4 / 3):
    """(camera position, target) in m from which the camera, looking along
    -CAMERA_DIRECTION, sees every point of ``points_m`` (N, 3), in a window
    of ``aspect`` (width / height) or wider (Meshcat's vertical field of
    view is CAMERA_FOV_DEG), with FRAMING_MARGIN (a share) to spare."""
    pts = np.asarray(points_m, dtype=float)
    back = CAMERA_DIRECTION / np.linalg.norm(CAMERA_DIRECTION)  # from the target towards the camera
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    tan_v = np.tan(np.radians(CAMERA_FOV_DEG) / 2) / (1 + FRAMING_MARGIN)
    tan_h = aspect * tan_v
    # centre the view on the points' extent across the image, then back off until all fit
    x, y = pts @ right, pts @ up
    target = right * (x.max() + x.min()) / 2 + up * (y.max() + y.min()) / 2 + back * float(np.mean(pts @ back))
    rel = pts - target
    x, y, depth = rel @ right, rel @ up, rel @ back  # depth: towards the camera
    distance = float(np.max(np.maximum(np.abs(x) / tan_h, np.abs(y) / tan_v) + depth))
    return target + back * distance, target


def caption_html(sc, robot, factor, deviation_m, names, t_end_s):
    """The page's title line (the magnification, large) and its caption:
    what is shown."""
    runs = ", ".join(f"{n}: {_color_name(n)}" for n in names)
    title = (f'<div id="{TITLE_ID}" style="position:fixed;left:8px;top:8px;z-index:10;'
             'background:rgba(255,255,255,0.85);padding:6px 10px;font:bold 20px sans-serif;border-radius:4px">'
             f'{_html(sc.name)}: deflection magnified <span id="robstiff-magnification">{factor:g}</span>&times;'
             '</div>')
    return title + (f'<div id="{CAPTION_ID}" style="position:fixed;right:8px;bottom:8px;max-width:40vw;z-index:10;'
            'background:rgba(255,255,255,0.85);padding:5px 8px;font:12px sans-serif;border-radius:4px">'
            f'<b>{_html(sc.name)}</b> ({_html(robot.manufacturer)} {_html(robot.model)}), {t_end_s:.1f} s simulated. '
            f'<b>Deflection magnified {factor:g}&times;</b>: each robot is '
            f'drawn at planned + {factor:g} &times; (simulated &minus; planned) joint angles, so its tool point '
            f'leaves the planned path by {factor:g} times its real deviation (largest real deviation '
            f'{deviation_m * 1e3:.3f} mm: the deflection under the cut and the servo\'s lag). Robots: {runs}; '
            'translucent grey: on the planned path. Lines: black, the planned tool path; coloured, each run\'s '
            f'magnified tool path. Workpiece boxes drawn {WORKPIECE_DEPTH_M * 1e3:.0f} mm deep. Where the robots '
            f'coincide, the blue one is drawn {ROBOT_INFLATE_M["compensated"] * 1e3:g} mm larger than the orange one '
            '(no flicker). Controls (top '
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
    planned_path = cell.path.positions(path_t)
    run_paths = {name: tool_points(robot, tool_m, q) for name, q in shown.items()}
    draw_cell(meshcat, sc, cell.workpiece, planned_path, run_paths)
    w = cell.workpiece
    boxes = [np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (top, top - WORKPIECE_DEPTH_M)])
             for (x0, x1), (y0, y1), top in zip(w.x_m, w.y_m, w.top_m)]
    robots = drawn_points(plant, context, instances, {"planned": q_plan, **shown})
    meshcat.SetCameraPose(*camera_pose(np.vstack([robots, *boxes, planned_path, *run_paths.values()])))

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

