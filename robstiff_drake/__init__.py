"""robstiff-drake: joint-stiffness models, identification and real-time
deflection compensation for machining robots, simulated with Drake.

Layout (one file per idea):
  robstiff_drake/model/      plain numpy physics: robot parameters, kinematics,
                             inverse kinematics, stiffness models, real-time path
  robstiff_drake/plant.py    the robot as a Drake MultibodyPlant
  robstiff_drake/commands/   the `robstiff` command line
"""

__version__ = "0.1.0"
