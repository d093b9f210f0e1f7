"""``robstiff make-urdf``: write a robot's description (URDF and a ROS-style
package.xml) into a folder, from its robot file, for Drake, ROS or a
viewer.  The simulations do not need it: they generate their own copy into
a cache folder (robstiff_drake/plant.py).  It never writes into the
installed package."""

from pathlib import Path

from robstiff_drake.errors import InputError
from robstiff_drake.io import check_outputs, write_atomic
from robstiff_drake.model.description import make_package_xml, make_urdf, package_name
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DATA_DIR, DIAGRAMS_DIR, MODELS_DIR
from robstiff_drake.progress import info


def wanted_files(robot, out):
    folder = Path(out) / package_name(robot)
    return {folder / "urdf" / f"{robot.name}.urdf": make_urdf(robot), folder / "package.xml": make_package_xml(robot)}


def run(*, check=False, out="robstiff-out/urdf", robot_yaml=None):
    robot = load_robot(robot_yaml)
    for packaged in (MODELS_DIR, DIAGRAMS_DIR, DATA_DIR):
        try:
            Path(out).resolve().relative_to(packaged.resolve())
        except ValueError:
            continue
        raise InputError(f"make-urdf --out {out}: inside the package's data folder {packaged}; choose another folder")
    wanted = wanted_files(robot, out)
    if check:
        stale = [str(p) for p, text in wanted.items() if not p.exists() or p.read_text() != text]
        if stale:
            raise InputError(f"make-urdf --check: out of date with {robot.source} (run `robstiff make-urdf "
                             f"--robot {robot_yaml or robot.name} --out {out}`): " + ", ".join(stale))
        print(f"{Path(out) / package_name(robot)} is up to date with {robot.source}")
        return 0
    check_outputs(inputs=[robot.source], files={f"--out ({p.name})": p for p in wanted})
    for path, text in wanted.items():
        write_atomic(path, text)
        info(f"wrote {path}")
    return 0
