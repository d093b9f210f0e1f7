"""``robstiff simulate ... --replay OUT.html``: the 3D replay opens in a real
headless browser (Debian's chromium, driven over the DevTools protocol),
without a server, and shows the robots, the workpiece and the tool paths:
the default camera frames all of them (every drawn corner projects inside
the view, the robots fill most of its height), the tool paths are tubes,
the magnification is on the page, and the robots' shapes never coincide
(each is drawn larger than the one inside it: no z-fighting); without
Meshcat's server the command stops before its simulation.

The browser test skips, with the reason printed, where chromium is not
installed (`.ci/run` installs it where it can)."""

import socket
import time

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.diagrams import replay
from robstiff_drake.model.robot import load_robot

from robstiff_drake.paths import DIAGRAMS_DIR

BLOCK = DIAGRAMS_DIR / "block_milling.yaml"

SCENE_JS = """(() => {
  if (typeof viewer === "undefined") return null;
  const meshes = [];
  viewer.scene.traverse(o => {
    if (!o.isMesh && !o.isLine) return;
    const path = [];
    for (let q = o; q; q = q.parent) path.unshift(q.name);
    meshes.push(path.filter(n => n).join("/"));
  });
  if (meshes.filter(p => p.startsWith("Scene/drake/")).length === 0) return null;
  const caption = document.getElementById("%s");
  return {meshes: meshes, caption: caption ? caption.textContent : null,
          magnification: (document.getElementById("robstiff-magnification") || {}).textContent,
          animation_s: viewer.animator && viewer.animator.mixer ? viewer.animator.mixer.time : null,
          clips: viewer.animator ? viewer.animator.actions.length : 0,
          title: (document.getElementById("%s") || {}).textContent,
          resources: performance.getEntriesByType("resource").map(r => r.name.slice(0, 40))};
})()""" % (replay.CAPTION_ID, replay.TITLE_ID)

# How far out each group of drawn objects reaches in the default camera's view: the largest |x|, |y| of
# its meshes' bounding-box corners in normalised device coordinates (inside the view: <= 1), and the
# vertical span of the robots (a share of the view's height, 2).
FRAMING_JS = """(() => {
  const cam = viewer.camera;
  viewer.scene.updateMatrixWorld(true);
  cam.updateMatrixWorld(true);
  const out = {};
  viewer.scene.traverse(o => {
    if (!o.isMesh || !o.visible) return;
    const path = [];
    for (let q = o; q; q = q.parent) path.unshift(q.name);
    const name = path.filter(n => n).join("/");
    const group = name.startsWith("Scene/drake/robots/") ? "robots" :
                  name.startsWith("Scene/cell/workpiece") ? "workpiece" :
                  name.startsWith("Scene/cell/tool_path") ? "tool_path" : null;
    if (!group) return;
    o.geometry.computeBoundingBox();
    const b = o.geometry.boundingBox;
    const g = out[group] || (out[group] = {reach: 0, ymin: 1e9, ymax: -1e9});
    for (const x of [b.min.x, b.max.x]) for (const y of [b.min.y, b.max.y]) for (const z of [b.min.z, b.max.z]) {
      const v = b.min.clone();
      v.set(x, y, z);
      v.applyMatrix4(o.matrixWorld).project(cam);
      g.reach = Math.max(g.reach, Math.abs(v.x), Math.abs(v.y));
      g.ymin = Math.min(g.ymin, v.y);
      g.ymax = Math.max(g.ymax, v.y);
    }
  });
  return out;
})()"""

SHOW_ONLY_JS = """(() => {
  viewer.scene.traverse(o => {
    const path = [];
    for (let q = o; q; q = q.parent) path.unshift(q.name);
    const name = path.filter(n => n).join("/");
    const keep = "Scene/drake/robots/%s";  // that robot, the nodes above it and the scene's other objects
    if (name.startsWith("Scene/drake/robots/")) o.visible = name.startsWith(keep) || keep.startsWith(name);
  });
  viewer.set_dirty();
  return true;
})()"""


@pytest.fixture(scope="module")
def replay_run(tmp_path_factory):
    """A short cut simulated with --replay (both runs); (html path, summary, seconds)."""
    import json

    tmp = tmp_path_factory.mktemp("replay")
    # a short cut: the block test's pass ends 40 mm into the block, no dwell
    text = BLOCK.read_text()
    assert "    - [1717.5, 0.0, 700.0]" in text and "dwell_s: 0.2" in text  # the block test's pass
    text = text.replace("    - [1717.5, 0.0, 700.0]", "    - [1560.0, 0.0, 700.0]").replace("dwell_s: 0.2",
                                                                                        "dwell_s: 0.0")
    scenario = tmp / "short_block.yaml"
    scenario.write_text(text)
    html = tmp / "replay.html"
    t0 = time.perf_counter()
    assert main(["simulate", str(scenario), "--out", str(tmp / "run"), "--replay", str(html), "--json",
                 str(tmp / "summary.json")]) == 0
    return html, json.loads((tmp / "summary.json").read_text()), time.perf_counter() - t0


def test_replay_file_is_self_contained(replay_run):
    html, summary, _ = replay_run
    text = html.read_text()
    info = summary["replay"]
    assert info["bytes"] == len(text.encode()) and info["magnification"] >= 1
    assert replay.CAPTION_ID in text and f"{info['magnification']:g}</span>&times;" in text
    # no server: the page loads no script or style from elsewhere and opens no connection
    assert "viewer.connect(" not in text and "<script src" not in text and "<link " not in text
    # the magnification makes the largest deviation about 150 mm (1, 2 or 5 times a power of ten)
    shown_mm = info["magnification"] * info["max_deviation_mm"]
    assert 0.15e3 / 2.5 <= shown_mm <= 0.15e3 + 1e-6


def test_replay_opens_in_a_headless_browser(replay_run):
    from headless_chromium import Chromium, Unavailable

    html, summary, sim_seconds = replay_run
    robot = load_robot()
    t0 = time.perf_counter()
    try:
        with Chromium() as page:
            page.open(html.resolve().as_uri())
            scene = page.wait_for(SCENE_JS, timeout_s=60)
            assert scene is not None, "the replay's scene did not load within 60 s"
            time.sleep(1.0)
            png = page.screenshot()
            later = page.evaluate(SCENE_JS)
            framing = page.evaluate(FRAMING_JS)
            alone = {}
            for run in replay.RUN_COLORS:  # each run's robot with the others hidden
                page.evaluate(SHOW_ONLY_JS % run)
                time.sleep(0.5)
                alone[run] = page.screenshot()
            page.evaluate(SHOW_ONLY_JS % "")
    except Unavailable as why:
        print(f"\nSKIPPED the browser test: {why}")
        pytest.skip(f"no headless browser: {why}")
    seconds = time.perf_counter() - t0
    print(f"\nreplay: {summary['replay']['bytes'] / 1e6:.2f} MB, simulated and written in {sim_seconds:.1f} s; "
          f"opened and checked in chromium in {seconds:.1f} s")

    # every link of each robot (two runs and the planned one) is in the scene, with the spindle
    links = [link.name for link in robot.links] + ["spindle"]
    for run in ("uncompensated", "compensated", "planned"):
        prefix = f"Scene/drake/robots/{run}/{robot.name}/"
        have = {p[len(prefix):].split("/")[0] for p in scene["meshes"] if p.startswith(prefix)}
        assert have == set(links), (run, sorted(have))
    assert any(p.startswith("Scene/cell/workpiece/box_0") for p in scene["meshes"])
    assert {f"Scene/cell/tool_path/{n}" for n in ("planned", "uncompensated_magnified", "compensated_magnified")} \
        <= set(scene["meshes"])
    # the default camera frames the robots, the workpiece and the tool paths; the robots fill most of its height
    print(f"framing (NDC): {framing}")
    for group in ("robots", "workpiece", "tool_path"):
        assert framing[group]["reach"] <= 1.0, (group, framing)
    assert framing["robots"]["ymax"] - framing["robots"]["ymin"] >= 1.2, framing
    # the page says the magnification, in its title line and its caption, and the animation is there and plays
    assert scene["magnification"] == f"{summary['replay']['magnification']:g}"
    assert f"deflection magnified {scene['magnification']}" in scene["title"]
    assert "Deflection magnified" in scene["caption"]
    assert scene["clips"] >= 1 and later["animation_s"] > scene["animation_s"]
    # everything it loaded came from the file itself (data: URLs), nothing from a server
    assert all(r.startswith(("data:", "file:")) for r in later["resources"]), later["resources"]

    # the robots are drawn: each run's colour (orange, blue) fills its share of the screenshot with the other
    # robots hidden, and the outer (compensated) one shows in the whole scene
    import io

    import matplotlib.image as mpimg

    def share(png_bytes, rgba):
        img = mpimg.imread(io.BytesIO(png_bytes), format="png")[..., :3]
        return np.all(np.abs(img - np.array(rgba[:3])) < 0.25, axis=-1).mean()

    for name, rgba in replay.RUN_COLORS.items():
        print(f"{name}: {share(alone[name], rgba):.3%} of the pixels alone, {share(png, rgba):.3%} with the others")
        assert share(alone[name], rgba) > 0.02, f"{name} robot not visible alone ({share(alone[name], rgba):.4%})"
    assert share(png, replay.RUN_COLORS["compensated"]) > 0.02


def test_the_robots_shapes_never_coincide():
    """No z-fighting: every box and cylinder of the compensated robot is at least 4 mm larger on each side
    than the uncompensated robot's, and the planned robot's 4 mm larger again."""
    import re

    robot = load_robot()

    def sizes(name):
        text = replay._urdf_with_color(robot, replay.RUN_COLORS.get(name, (0, 0, 0, 1)),
                                       inflate_m=replay.ROBOT_INFLATE_M[name])
        boxes = [[float(v) for v in m.split()] for m in re.findall(r'<box size="([^"]*)"', text)]
        cylinders = [[float(v) for v in m] for m in re.findall(r'<cylinder radius="([^"]*)" length="([^"]*)"', text)]
        return np.array(sum(boxes, [])), np.array(sum(cylinders, []))

    inner = sizes("uncompensated")
    for outer_name, inner_name in (("compensated", "uncompensated"), ("planned", "compensated")):
        outer, inner = sizes(outer_name), sizes(inner_name)
        assert np.all(outer[0] - inner[0] >= 2 * 0.004 - 1e-9)  # box sizes: 4 mm on each side
        assert np.all(outer[1] - inner[1] >= 0.004 - 1e-9)  # cylinder radius 4 mm, length 8 mm


def test_the_tool_path_is_a_tube_around_the_path():
    path = np.column_stack([np.linspace(1.5, 1.7, 30), np.zeros(30), np.full(30, 0.7)])
    vertices, faces = replay.tube_mesh(path, 0.006)
    v = vertices.T
    # every vertex is 6 mm from the path's line, and the faces index the vertices
    assert np.allclose(np.hypot(v[:, 1], v[:, 2] - 0.7), 0.006)
    assert faces.min() == 0 and faces.max() == len(v) - 1 and faces.shape[0] == 3


def test_replay_needs_meshcat_before_the_simulation(tmp_path, capsys, monkeypatch):
    """No Meshcat server (its port taken): one line, exit 2, nothing simulated."""
    busy = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    try:
        with pytest.raises(Exception) as e:
            replay.start_meshcat(port=port)
        assert type(e.value).__name__ == "InputError" and "Meshcat cannot start" in str(e.value)
    finally:
        busy.close()

    start = replay.start_meshcat

    def no_server(port=None):
        return start(port=port_in_use)

    busy = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port_in_use = busy.getsockname()[1]
    monkeypatch.setattr(replay, "start_meshcat", no_server)
    from robstiff_drake.commands import simulate

    def must_not_run(**kwargs):
        raise AssertionError("simulated although the replay cannot be recorded")

    monkeypatch.setattr(simulate, "simulate", must_not_run)
    try:
        code = main(["simulate", str(BLOCK), "--out", str(tmp_path / "run"), "--replay",
                     str(tmp_path / "r.html")])
    finally:
        busy.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("robstiff: error: --replay: Meshcat cannot start"), err
    assert not (tmp_path / "run").exists() and not (tmp_path / "r.html").exists()


def test_replay_path_must_be_html(tmp_path, capsys):
    code = main(["simulate", str(BLOCK), "--out", str(tmp_path / "run"), "--replay",
                 str(tmp_path / "r.png")])
    assert code == 2 and "ending in .html" in capsys.readouterr().err


def test_nice_factor():
    assert [replay.nice_factor(x) for x in (0.3, 1.0, 1.9, 2.0, 4.99, 5.0, 99.0, 105.0, 730.0)] == \
        [1.0, 1.0, 1.0, 2.0, 2.0, 5.0, 50.0, 100.0, 500.0]
