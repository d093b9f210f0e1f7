"""``robstiff calibrate-payload DATA.csv``: the wrist sensor's payload (mass,
centre of mass, force and torque bias) from static readings."""


from robstiff_drake.commands.options import parse_vector
from robstiff_drake.io import Warnings, check_outputs, emit_json, staged_outputs, write_atomic
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def run(*, data, json_out=None, yaml_out=None, mount_rpy=None, robot_yaml=None):
    check_outputs(inputs=[data, robot_yaml], files={"--json": json_out, "--yaml": yaml_out})
    robot = load_robot(robot_yaml)
    mount = (0.0, 0.0, 0.0) if mount_rpy is None else parse_vector(mount_rpy, 3, "--mount-rpy")
    # scipy comes with these: after the checks of the arguments
    from robstiff_drake.identification.stiffness.campaign import read_payload_campaign
    from robstiff_drake.identification.stiffness.payload import calibrate, check_payload_fit, t95, yaml_block

    warnings = Warnings()
    campaign = read_payload_campaign(data, robot)
    fit = calibrate(robot, campaign, mount_rpy_deg=mount)
    warnings.extend_from(check_payload_fit(fit, robot, campaign.path))
    block = yaml_block(fit, data, robot.name)
    with staged_outputs():  # both files or neither
        if json_out is not None:
            emit_json({
                "data": campaign.path,
                "robot": robot.name,
                "mass_kg": fit.mass_kg,
                "mass_std_kg": fit.mass_std_kg,
                "com_mm": fit.com_m * 1e3,
                "com_std_mm": fit.com_std_m * 1e3,
                "force_bias_N": fit.force_bias_N,
                "torque_bias_Nm": fit.torque_bias_Nm,
                "rms_force_N": fit.rms_force_N,
                "rms_torque_Nm": fit.rms_torque_Nm,
                "n_configurations": fit.n_configurations,
                "n_gravity_directions": fit.n_directions,
                "sensor_mount_rpy_deg": fit.mount_rpy_deg,
                "residuals": [{"line": int(ln), "force_N": f, "torque_Nm": t}
                              for ln, f, t in zip(campaign.lines, fit.residual_force_N, fit.residual_torque_Nm)],
                "yaml": block,
                "warnings": list(warnings),
            }, json_out)
        if yaml_out is not None:
            write_atomic(yaml_out, block)
    if json_out != "-":
        t = t95(3 * fit.n_configurations - 4)
        print(f"payload from {campaign.path}: {fit.n_configurations} configurations, "
              f"{fit.n_directions} distinct gravity directions in the sensor frame")
        print(f"  mass             {fit.mass_kg:10.4f} kg   +- {t * fit.mass_std_kg:.4f} (95 %)")
        c, cs = fit.com_m * 1e3, fit.com_std_m * 1e3
        print("  centre of mass   (" + ", ".join(f"{v:.2f}" for v in c) + ") mm   +- ("
              + ", ".join(f"{2 * v:.2f}" for v in cs) + ") (about 95 %)")
        print("  force bias       (" + ", ".join(f"{v:.3f}" for v in fit.force_bias_N) + ") N")
        print("  torque bias      (" + ", ".join(f"{v:.4f}" for v in fit.torque_bias_Nm) + ") N*m")
        print(f"  residual RMS     {fit.rms_force_N:.3f} N, {fit.rms_torque_Nm:.4f} N*m")
        print()
        print(block, end="")
    wrote(json_out, to_stderr=json_out == "-")
    wrote(yaml_out, "the gravity-removal block (compensate --payload, a scenario's model.payload_yaml)",
          to_stderr=json_out == "-")
    return 0
