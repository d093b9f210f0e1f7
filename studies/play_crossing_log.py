"""Where the compensator's hysteretic play law puts joint 2's gear in its
gap against where the plant's gear is, along the balanced pass
(tests/data/balanced_y_pass.yaml, predictive compensation, play b on
joint 2 in the plant and in the compensator's model, the law at the true
b): every ``--every-s`` from ``--from-s`` to ``--to-s``, the plant's
twist (motor minus link angle, urad: its gear's position in the gap plus
its elastic twist), the model's position in the gap and its reference at
the touch-off (urad, the Drake Context's discrete state of the
deflection prediction block, recorded at each update), the gear torque
the model predicts (N*m), the predicted joint deflection and the
correction (urad) and the tool's depth error (commanded minus actual
tool z, mm: positive cuts more), then the face's statistics.

    python3 studies/play_crossing_log.py [--b-urad 150] [--friction-Nm F] [--hard-landing] [--landing-fraction F] [--from-s 2.0] [--to-s 3.2] [--every-s 0.04]
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from play_diagnosis import BALANCED, predictive, with_play  # noqa: E402

from robstiff_drake.commands.simulate import simulate  # noqa: E402
from robstiff_drake.systems import deflection_prediction  # noqa: E402


def recorded_updates():
    """Wrap the prediction block's periodic update to record (t, position,
    reference, predicted gear torque) of joint 2; returns the list it fills."""
    rows = []
    update = deflection_prediction.DeflectionPrediction._update_play

    def recording(self, context, discrete_state):
        tau, static, pos, ref, _, _ = self._play(context)
        rows.append((context.get_time(), pos[1], ref[1], (static - tau)[1]))
        return update(self, context, discrete_state)

    deflection_prediction.DeflectionPrediction._update_play = recording
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--b-urad", type=float, default=150.0)
    ap.add_argument("--friction-Nm", type=float, default=None, help="the law's friction (default: the fallback)")
    ap.add_argument("--hard-landing", action="store_true",
                    help="the law's crossing without its soft landing (as it was before it)")
    ap.add_argument("--landing-fraction", type=float, default=None,
                    help="the law's play_hysteresis.LANDING_FRACTION (default: the module's)")
    ap.add_argument("--from-s", type=float, default=2.0)
    ap.add_argument("--to-s", type=float, default=3.2)
    ap.add_argument("--every-s", type=float, default=0.04)
    args = ap.parse_args()
    b = args.b_urad * 1e-6
    text = with_play(with_play(predictive(BALANCED), b), b, "model", "hysteretic")
    if args.friction_Nm is not None:
        f = args.friction_Nm
        text = text.replace("  lost_motion_law: hysteretic\n",
                            f"  lost_motion_law: hysteretic\n  lost_motion_friction_Nm: [{f:g}, {f:g}, {f:g}, {f:g}, {f:g}, {f:g}]\n")
    rows = recorded_updates()
    if args.landing_fraction is not None:
        from robstiff_drake.model import play_hysteresis

        play_hysteresis.LANDING_FRACTION = args.landing_fraction
    if args.hard_landing:
        from robstiff_drake.model import compensator, play_hysteresis

        def hard(self, tau_process, static_torque, positions, rates, inertia_kgm2, dt_s):
            carried = np.asarray(static_torque, dtype=float) - np.asarray(tau_process, dtype=float)
            return play_hysteresis.crossing_step(positions, rates, carried, self.lost, self.friction, inertia_kgm2,
                                                 dt_s)

        compensator.DeflectionModel.play_crossing = hard
    with tempfile.TemporaryDirectory(prefix="robstiff-play-log-") as tmp:
        scenario = Path(tmp) / "play.yaml"
        scenario.write_text(text)
        _, results = simulate(scenario=str(scenario), compensation="on")
    r = results[0]
    t, x = r.logs["state"]
    _, motor = r.logs["motor"]
    twist = motor[:, 1] - x[:, 1]
    td, dq = r.logs["dq"]
    _, corr = r.logs["correction"]
    ts, commanded, actual = tool_depth(r)
    rec = np.array(rows)
    print("| t (s) | plant's twist (urad) | model's position in the gap (urad) | model's reference (urad) | predicted gear "
          "torque (N*m) | predicted dq2 (urad) | correction q2 (urad) | tool depth error (mm) |")
    print("|---|---|---|---|---|---|---|---|")
    for tt in np.arange(args.from_s, args.to_s + 1e-9, args.every_s):
        i, j = np.searchsorted(t, tt), min(np.searchsorted(rec[:, 0], tt), len(rec) - 1)
        k, m = min(np.searchsorted(td, tt), len(td) - 1), min(np.searchsorted(ts, tt), len(ts) - 1)
        print(f"| {tt:.2f} | {twist[i] * 1e6:+.1f} | {rec[j, 1] * 1e6:+.1f} | {rec[j, 2] * 1e6:+.1f} | {rec[j, 3]:+.1f} | "
              f"{dq[k, 1] * 1e6:+.1f} | {corr[k, 1] * 1e6:+.1f} | {commanded[m] - actual[m]:+.4f} |")
    s = r.surface_error_mm
    print(f"compensated face, mean / rms / max abs (mm): {s['mean']:+.4f} / {s['rms']:.4f} / {s['max_abs']:.4f}")


def tool_depth(r):
    """(times s, commanded tool z mm, actual tool z mm) of a run (as simulate's timeseries CSV)."""
    from robstiff_drake.model import kinematics as kin

    t, x = r.logs["state"]
    T = kin.frames(r.cell.robot.dh, x[:, :6])[:, 6]
    z = (T[:, :3, 3] + T[:, :3, :3] @ r.cell.tool_m)[:, 2]
    return t, r.cell.path.positions(t)[:, 2] * 1e3, z * 1e3


if __name__ == "__main__":
    main()
