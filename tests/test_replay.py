"""``robstiff simulate ... --replay OUT.html``: the 3D replay opens in a real
headless browser (Debian's chromium, driven over the DevTools protocol),
without a server, and shows the robots, the workpiece and the tool paths;
without Meshcat's server the command stops before its simulation.

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
          resources: performance.getEntriesByType("resource").map(r => r.name.slice(0, 40))};
})()""" % replay.CAPTION_ID


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
    # the page says the magnification, and the animation is there and plays
    assert scene["magnification"] == f"{summary['replay']['magnification']:g}"
    assert "Deflection magnified" in scene["caption"]
    assert scene["clips"] >= 1 and later["animation_s"] > scene["animation_s"]
    # everything it loaded came from the file itself (data: URLs), nothing from a server
    assert all(r.startswith(("data:", "file:")) for r in later["resources"]), later["resources"]

    # the robots are drawn: the screenshot has the runs' colours (orange, blue)
    import io

    import matplotlib.image as mpimg

    img = mpimg.imread(io.BytesIO(png), format="png")[..., :3]
    for name, rgba in replay.RUN_COLORS.items():
        near = np.all(np.abs(img - np.array(rgba[:3])) < 0.25, axis=-1)
        print(f"{name}: {near.mean():.3%} of the pixels")
        assert near.mean() > 0.002, f"{name} robot not visible in the screenshot ({near.mean():.4%} of pixels)"


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
