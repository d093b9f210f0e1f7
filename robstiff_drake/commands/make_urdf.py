"""``robstiff make-urdf``: regenerate the Drake-loadable robot description
(models/irb6400/urdf/irb6400.urdf and package.xml) from the YAML file."""

from robstiff_drake.errors import InputError
from robstiff_drake.io import write_atomic
from robstiff_drake.model.description import make_package_xml, make_urdf
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import IRB6400_PACKAGE_XML, IRB6400_URDF


def run(*, check=False, robot_yaml=None):
    robot = load_robot(robot_yaml)
    wanted = {IRB6400_URDF: make_urdf(robot), IRB6400_PACKAGE_XML: make_package_xml()}
    if check:
        stale = [str(p) for p, text in wanted.items() if not p.exists() or p.read_text() != text]
        if stale:
            raise InputError("make-urdf --check: out of date (run `robstiff make-urdf`): " + ", ".join(stale))
        print("models/irb6400 is up to date with " + robot.source)
        return 0
    for path, text in wanted.items():
        write_atomic(path, text)
        print(f"wrote {path}")
    return 0
