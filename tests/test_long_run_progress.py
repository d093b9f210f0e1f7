"""Long runs say how far they are: `kg-study --grid 20` (8000 IK
solutions before its cases) and `stiffness-map --resolution 301` (181,202)
step a progress bar (robstiff_drake/progress.py: a bar on a terminal, log
lines elsewhere) over every grid point, from the first one.  Before, the
IK of both ran minutes without a word."""

import numpy as np

from robstiff_drake.model.robot import load_robot


class Recorder:
    """A stand-in for progress.progress: records each bar's total and steps."""

    def __init__(self):
        self.bars = []

    def __call__(self, total, enabled=None, desc="", unit="it", **kwargs):
        rec = self

        class Bar:
            def __init__(self):
                self.total, self.desc, self.n = total, desc, 0
                rec.bars.append(self)

            def update(self, n=1):
                self.n += n

            def close(self):
                pass

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                return False

        return Bar()


def test_kg_study_steps_a_bar_over_its_workspace_poses(monkeypatch):
    from robstiff_drake.commands import kg_study

    rec = Recorder()
    monkeypatch.setattr(kg_study, "progress", rec)
    kg_study.study(load_robot(), grid=3)
    ik_bar = next(b for b in rec.bars if "IK" in b.desc)
    assert ik_bar.total == 27 and ik_bar.n == 27 and rec.bars[0] is ik_bar  # the poses' bar comes first


def test_stiffness_map_steps_a_bar_over_every_point(monkeypatch):
    from robstiff_drake.commands import stiffness_map

    rec = Recorder()
    monkeypatch.setattr(stiffness_map, "progress", rec)
    robot = load_robot()
    stiffness_map.make_map(robot, tool_m=np.asarray(robot.payload.tool_point_m), resolution=5)
    assert [(b.total, b.n) for b in rec.bars] == [(50, 50)]
