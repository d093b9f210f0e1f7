"""Campaign size (issue 19 item 6): `identify` and `diagnose` on 100,000 rows
(the size `robstiff synth` allows) in memory linear in the rows, run in a
subprocess under an address-space cap (resource.setrlimit) far below what
the dense (3N)^2 matrices of the lack-of-fit test needed (720 GB here; an
8,000-row campaign took 8 GB and crashed before).  The diagnosis runs the
memory-heavy steps (screens, folds, floor and replicates, lack of fit,
residual structure, intervals) with one named candidate, to stay fast; the
lack-of-fit moments themselves are checked against the dense formula on
small campaigns."""

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from robstiff_drake.identification.diagnosis import noise_floor as nf
from robstiff_drake.identification.diagnosis.cross_validation import splits
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot

ROWS = 100_000
CAP_BYTES = 3 * 1024**3  # virtual memory of the whole process, Python, numpy and scipy included


def _campaign_csv(path, n=ROWS, loads_per_pose=4, seed=0):
    """A six-spring campaign written fast with numpy (the size, not the physics, is under test)."""
    robot = load_robot()
    rng = np.random.default_rng(seed)
    n_poses = n // loads_per_pose
    lo, hi = robot.q_lower_rad * 0.5, robot.q_upper_rad * 0.5
    q = np.repeat(rng.uniform(lo, hi, size=(n_poses, 6)), loads_per_pose, axis=0)
    f = rng.normal(size=(n, 3))
    f *= 300.0 / np.linalg.norm(f, axis=1, keepdims=True)
    tool = np.array([0.0, 0.0, 0.35])
    J = kin.jacobian(robot.dh, q, tool)
    tau = np.einsum("nrj,nr->nj", J[:, :3], f)
    d = np.einsum("nrj,nj->nr", J[:, :3], tau / robot.joint_stiffness_Nm_per_rad) * 1e3
    d += rng.normal(scale=0.01, size=d.shape)
    pose = np.repeat(np.arange(n_poses), loads_per_pose)
    table = np.column_stack([pose, np.rad2deg(q), f, d])
    with open(path, "w") as fh:
        fh.write("# tool_mm: 0, 0, 350\npose,q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz\n")
        np.savetxt(fh, table, fmt=["%d"] + ["%.6f"] * 6 + ["%.4f"] * 3 + ["%.6f"] * 3, delimiter=",")
    return path


SCRIPT = textwrap.dedent("""
    import json, resource, sys
    resource.setrlimit(resource.RLIMIT_AS, ({cap}, {cap}))
    from robstiff_drake.commands.main import main
    from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
    from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
    from robstiff_drake.model.robot import load_robot
    data = sys.argv[1]
    code = main(["--quiet", "identify", data, "--json", sys.argv[2]])
    robot = load_robot()
    camp = read_stiffness_campaign(data, robot)
    d = diagnose(robot, camp, tool_m=camp.tool_mm / 1e3, noise_mm=0.01, candidates=["lost_motion"],
                 dictionary=False)
    print(json.dumps({{"identify": code, "n": len(camp), "explains": d.explains_data, "rms_after": d.rms_after_mm,
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
""")


def test_100k_rows_under_a_memory_cap(tmp_path):
    data = _campaign_csv(tmp_path / "big.csv")
    out = tmp_path / "id.json"
    proc = subprocess.run([sys.executable, "-c", SCRIPT.format(cap=CAP_BYTES), str(data), str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res["identify"] == 0 and res["n"] == ROWS
    k = np.array(json.loads(out.read_text())["joint_stiffness_Nm_per_rad"])
    np.testing.assert_allclose(k[:5], load_robot().joint_stiffness_Nm_per_rad[:5], rtol=0.01)
    assert res["explains"] is True and res["rms_after"] == pytest.approx(0.01, rel=0.05)
    print(f"100,000 rows: peak RSS {res['maxrss_mb']:.0f} MB under a {CAP_BYTES / 1024**3:.0f} GB address-space cap")


@pytest.mark.parametrize("seed", [1, 2])
def test_lack_of_fit_moments_equal_the_dense_formula(seed):
    rng = np.random.default_rng(seed)
    n, p = 60, 7
    X = rng.normal(size=(3 * n, p))
    groups = rng.integers(0, n // 3, size=n)
    rows = np.arange(n)
    folds = splits(rows, groups)
    M = nf.cv_map(X, folds, rows)
    for rho in (0.0, 0.5):
        E0, V0 = nf.dense_moments(M, groups, rho)
        E1, V1 = nf.moments(X, folds, rows, groups, rho)
        assert E1 == pytest.approx(E0, rel=1e-10) and V1 == pytest.approx(V0, rel=1e-10)
