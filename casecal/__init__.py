"""casecal: kinematic calibration of serial robot arms.

A robot is a CasADi graph of its Denavit-Hartenberg chain, with exact Jacobians of the
end-effector position with respect to every geometric parameter. See DESIGN.md for the data
flow and README.md for the commands.
"""

from . import poses
from .catalog import load_robot, robot_to_toml, robots
from .errors import CalibrationError
from .measurements import Measurements, simulate
from .robot import Frame, Joint, Robot

__all__ = [
    "CalibrationError",
    "Frame",
    "Joint",
    "Measurements",
    "Robot",
    "load_robot",
    "poses",
    "robot_to_toml",
    "robots",
    "simulate",
]
__version__ = "0.1.0"
