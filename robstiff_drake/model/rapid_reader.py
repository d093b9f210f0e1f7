"""A small reader of the RAPID modules model/rapid_writer.py writes (its
features only: ``MODULE``, ``PERS``/``CONST`` declarations, one ``PROC
main()`` of ``MoveL`` / ``MoveC`` to inline ``robtarget``s, ``!``
comments), so that a written module can be run back through the
simulation.  Plain Python; no Drake.  Units: mm and RAPID's quaternions
(q1 the scalar part), in the work object's frame."""

import re
from dataclasses import dataclass

import numpy as np

_ROBTARGET = r"\[\[([^\]]*)\],\[([^\]]*)\],\[([^\]]*)\],\[([^\]]*)\]\]"
_MOVE = re.compile(r"(MoveL|MoveC) (.*),([A-Za-z][A-Za-z0-9_]*),([A-Za-z][A-Za-z0-9_]*),"
                   r"([A-Za-z][A-Za-z0-9_]*)\\WObj:=([A-Za-z][A-Za-z0-9_]*);")


class RapidReadError(ValueError):
    """A module line this reader does not take: ``line`` (1-based)."""

    def __init__(self, message, line):
        super().__init__(f"line {line}: {message}")
        self.line = line


@dataclass
class RapidMove:
    """One motion instruction: ``MoveL`` or ``MoveC``; its targets (one,
    or the circle point then the end) as (position mm, quaternion)."""

    instruction: str
    targets: list
    speed: str
    line: int


def read_moves(text):
    """The module's motion instructions (RapidMove list), in order."""
    moves = []
    for k, raw in enumerate(text.splitlines(), start=1):
        ln = raw.strip()
        if not ln.startswith(("MoveL ", "MoveC ")):
            continue
        m = _MOVE.fullmatch(ln)
        if m is None:
            raise RapidReadError("a motion instruction this reader does not take", k)
        targets = []
        for pos, quat, _, _ in re.findall(_ROBTARGET, m.group(2)):
            p = np.array([float(v) for v in pos.split(",")])
            q = np.array([float(v) for v in quat.split(",")])
            if p.shape != (3,) or q.shape != (4,) or abs(np.linalg.norm(q) - 1.0) > 1e-5:
                raise RapidReadError("a robtarget without a position (3) and a unit quaternion (4)", k)
            targets.append((p, q))
        if len(targets) != (2 if m.group(1) == "MoveC" else 1):
            raise RapidReadError(f"{m.group(1)} with {len(targets)} targets", k)
        moves.append(RapidMove(m.group(1), targets, m.group(3), k))
    return moves


def rotation(quat):
    """The rotation matrix (3x3) of a RAPID quaternion [q1 (scalar), q2, q3, q4]."""
    w, x, y, z = np.asarray(quat, dtype=float) / np.linalg.norm(quat)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
