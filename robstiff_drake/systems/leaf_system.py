"""The project's LeafSystem: pydrake's, with the answer to one question
Drake asks every Python system after every plant step made cheap.

After each plant step (the MultibodyPlant's unrestricted update) Drake's
Simulator asks every system for its witness functions.  For a Python
system the binding first looks for a Python override named
``DoGetWitnessFunctions``; pybind11 remembers an attribute that is a bound
C++ function as "not overridden" (its inactive-override cache) and goes
straight to C++ from then on, but an attribute that is missing it looks up
again at every call, with an AttributeError raised and cleared each time.
So this class names the C++ binding: Drake then runs LeafSystem's own
DoGetWitnessFunctions, as it does without the attribute (the witness
functions a system declares; the project's declare none), and the look-up
happens once.  Measured (2026-12-07, benchmarks/instruction_counts.py,
the block pass, plain compensation, 4 Python systems and 2 plant steps a
4 ms tick): the witness functions 63.9 k of 1,155.7 k instructions a
tick before, 15.3 k after; the answer is the same.
A subclass that overrides DoGetWitnessFunctions in Python is still called.
"""

from pydrake.systems.framework import LeafSystem as _DrakeLeafSystem


class LeafSystem(_DrakeLeafSystem):
    """pydrake's LeafSystem; see the module docstring."""

    # a bound C++ function: pybind11 caches it as "no Python override" (not a call: Drake runs its own)
    DoGetWitnessFunctions = _DrakeLeafSystem.GetWitnessFunctions
