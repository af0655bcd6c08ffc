"""casecal: kinematic calibration of serial robot arms.

A robot is a CasADi graph of its Denavit-Hartenberg chain, with exact Jacobians of the
end-effector position with respect to every geometric parameter. See DESIGN.md for the data
flow and README.md for the commands.
"""

from .data.files import read_csv, write_csv
from .data.measurements import Measurements, simulate
from .design import poses
from .design.campaign import calibrate_until
from .errors import CalibrationError, CalibrationWarning
from .identification.analysis import Observability, observability
from .identification.calibration import Calibration
from .identification.fit import identify
from .identification.validation import Validation, validate
from .model.catalog import load_robot, robot_to_toml, robots
from .model.robot import Frame, Joint, Robot

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


def _keep_old_module_paths() -> None:
    """Let scripts written for the flat layout of casecal 0.1 (``casecal.catalog``,
    ``from casecal.parameters import select`` …) keep working after the move into
    packages: each old path names the module that now holds the same code."""
    import importlib
    import sys

    moved = {
        "parameters": "model.parameters",
        "kinematics": "model.kinematics",
        "robot": "model.robot",
        "frames": "model.frames",
        "catalog": "model.catalog",
        "measurements": "data.measurements",
        "measurement_files": "data.files",
        "identifiability": "identification.analysis",
        "solvers": "identification.solvers",
        "calibration": "identification.calibration",
        "summary": "identification.summary",
        "validation": "identification.validation",
        "distances": "identification.distances",
        "campaign": "design.campaign",
        "study": "studies.engine",
    }
    for old, new in moved.items():
        module = importlib.import_module(f"{__name__}.{new}")
        sys.modules.setdefault(f"{__name__}.{old}", module)
        globals().setdefault(old, module)


_keep_old_module_paths()
