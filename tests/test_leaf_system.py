"""The project's LeafSystem base (systems/leaf_system.py): every project
system derives from it, its witness functions are LeafSystem's own, and a
Python override of DoGetWitnessFunctions is still called."""

import importlib
import pkgutil

from pydrake.systems.framework import LeafSystem as DrakeLeafSystem
from pydrake.systems.framework import WitnessFunctionDirection

import robstiff_drake.diagrams
import robstiff_drake.systems
from robstiff_drake.systems.leaf_system import LeafSystem
from robstiff_drake.systems.wrist_sensor import WrenchGuard


def _subclasses(cls):
    todo, found = list(cls.__subclasses__()), []
    while todo:
        c = todo.pop()
        todo.extend(c.__subclasses__())
        found.append(c)
    return found


def test_every_project_system_derives_from_the_project_base():
    for package in (robstiff_drake.systems, robstiff_drake.diagrams):
        for mod in pkgutil.iter_modules(package.__path__):
            importlib.import_module(f"{package.__name__}.{mod.name}")
    ours = [c for c in _subclasses(DrakeLeafSystem) if c.__module__.startswith("robstiff_drake.")]
    assert len(ours) >= 15  # (the systems and the diagrams' own: they were all found)
    strays = [f"{c.__module__}.{c.__name__}" for c in ours if not issubclass(c, LeafSystem)]
    assert not strays, f"derive these from robstiff_drake.systems.leaf_system.LeafSystem: {strays}"


def test_witness_functions_are_leaf_systems_own():
    guard = WrenchGuard(rate_hz=250.0, max_jump_N=100.0)
    context = guard.CreateDefaultContext()
    for _ in range(3):  # (the first call looks the override up; the next ones find it cached)
        assert guard.GetWitnessFunctions(context) == []


class _Crossing(LeafSystem):
    """One witness function, given by a Python override."""

    def __init__(self):
        super().__init__()
        self.DeclareContinuousState(1)
        self.witness = self.MakeWitnessFunction("crossing", WitnessFunctionDirection.kCrossesZero,
                                                lambda context: context.get_time() - 1.0)
        self.asked = 0

    def DoGetWitnessFunctions(self, context):
        self.asked += 1
        return [self.witness]


def test_a_python_override_of_witness_functions_is_still_called():
    system = _Crossing()
    context = system.CreateDefaultContext()
    witnesses = system.GetWitnessFunctions(context)
    assert system.asked == 1
    assert witnesses == [system.witness]
