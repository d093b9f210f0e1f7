"""studies/chip_coupling_stability.py's finding (issue 29), kept: on the
paper's block (its forces, draw 0) at mid-pass the arm with the
regenerative chip is unstable in continuous time at the coupled mode of
arm modes 4 and 5, its low-frequency limit (a velocity coupling) is
stable, the plant's scheme with the chip over a tooth every step converges
to that root as the step shrinks (the divergence is the physics', not the
step's), and the plant's own law (the program's direction, the feed at
2 Hz) is stable; at the block's own forces the regenerative chip is stable."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import chip_coupling_stability as study  # noqa: E402
import paper_reproduction as pr  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.model import chip_coupling as cc  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.systems.milling_force import FEED_CUTOFF_HZ, chip_window_s  # noqa: E402

MID = np.array([1.6, 0.0, 0.7])


@pytest.fixture(scope="module")
def block():
    robot = load_robot()
    cut = study.Cut(pr.paper_scenario("block", robot, 0), robot)
    arm, jm = cut.arm(MID)
    return robot, cut, arm, cut.chip(MID)


def test_the_regenerative_chip_chatters_on_the_paper_block_and_its_velocity_limit_does_not(block):
    _, cut, arm, chip = block
    s = study.exact_rightmost(arm, chip)
    assert s.real > 10.0 and 55.0 < abs(s.imag) / (2 * np.pi) < 80.0
    assert abs(cc.pade_roots(arm, chip, 4, study.MAX_HZ)[0] - s) < 1e-3 * abs(s)
    assert cc.rightmost(np.linalg.eigvals(cc.velocity_law_matrix(arm, chip))).real < 0
    assert cc.rightmost(np.linalg.eigvals(arm.A)).real < 0


def test_the_scheme_converges_to_the_continuous_root_and_the_plants_law_is_stable(block):
    _, cut, arm, chip = block
    s = study.exact_rightmost(arm, chip)
    g = [cc.growth_rate_per_s(cc.scheme_map(arm, chip, h), h) for h in (0.5e-3, 0.25e-3, 0.125e-3)]
    assert g[0] > g[1] > g[2] > s.real > 0
    assert g[2] - s.real < 0.5 * (g[1] - s.real) + 1e-9
    rev = chip_window_s(cut.cutter)
    plant = cc.scheme_map(arm, chip, 0.5e-3, period_steps=8, window_s=rev, along=(1.0, 0.0), cutoff_hz=FEED_CUTOFF_HZ)
    assert cc.spectral_radius(plant) < 1.0


def test_the_block_at_its_own_forces_is_stable(block):
    robot = block[0]
    own = study.Cut(load_scenario(ROOT / "diagrams" / "block_milling.yaml"), robot)
    assert study.exact_rightmost(own.arm(MID)[0], own.chip(MID)).real < 0
