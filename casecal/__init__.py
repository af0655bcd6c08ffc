"""casecal: kinematic calibration of serial robot arms.

A robot is a CasADi graph of its Denavit-Hartenberg chain, with exact Jacobians of the
end-effector position with respect to every geometric parameter. See DESIGN.md for the data
flow and README.md for the commands.
"""

from . import poses
from .calibration import Calibration
from .campaign import calibrate_until
from .catalog import load_robot, robot_to_toml, robots
from .errors import CalibrationError, CalibrationWarning
from .identifiability import Observability, observability
from .identification import identify
from .measurement_files import read_csv, write_csv
from .measurements import Measurements, simulate
from .robot import Frame, Joint, Robot
from .validation import Validation, validate

__all__ = [
    "Calibration",
    "CalibrationError",
    "CalibrationWarning",
    "Frame",
    "Joint",
    "Measurements",
    "Observability",
    "Robot",
    "Validation",
    "calibrate_until",
    "identify",
    "load_robot",
    "observability",
    "poses",
    "read_csv",
    "robot_to_toml",
    "robots",
    "simulate",
    "validate",
    "write_csv",
]
__version__ = "0.1.0"
