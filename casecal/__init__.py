"""casecal: kinematic calibration of serial robot arms.

A robot is a CasADi graph of its kinematic chain, with exact Jacobians of the end-effector
position with respect to every parameter. See DESIGN.md for the data flow and README.md for
the commands.

The public names below are loaded on first use (PEP 562), so ``import casecal`` and the
``casecal`` command start at once and Ctrl-C is answered from the first moment.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

__version__ = "0.1.0"

_PUBLIC = {
    "Calibration": "identification.calibration",
    "CalibrationError": "errors",
    "CalibrationWarning": "errors",
    "CameraSetup": "observations.simulate",
    "Checkerboard": "observations.target",
    "Frame": "model.robot",
    "Intrinsics": "observations.camera",
    "Joint": "model.robot",
    "Measurements": "data.measurements",
    "Observability": "identification.analysis",
    "PixelMeasurements": "observations.pixels",
    "Robot": "model.robot",
    "Validation": "identification.validation",
    "calibrate_until": "design.campaign",
    "compare_models": "identification.compare",
    "compensate": "model.compensate",
    "identify": "identification.fit",
    "load_robot": "model.catalog",
    "observability": "identification.analysis",
    "read_csv": "data.files",
    "robot_to_toml": "model.catalog",
    "robots": "model.catalog",
    "save_robot": "model.save",
    "select_views": "observations.simulate",
    "simulate": "data.measurements",
    "simulate_camera": "observations.pixels",
    "simulate_contact": "data.measurements",
    "validate": "identification.validation",
    "write_csv": "data.files",
}
_MODULES = {"poses": "design.poses"}

_MOVED = {
    # module paths of casecal 0.1's flat layout, kept for scripts that import them
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

__all__ = sorted([*_PUBLIC, *_MODULES])


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(f"{__name__}.{_PUBLIC[name]}"), name)
    elif name in _MODULES or name in _MOVED:
        value = importlib.import_module(f"{__name__}.{(_MODULES | _MOVED)[name]}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_PUBLIC, *_MODULES, *_MOVED])


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """``import casecal.catalog`` (casecal 0.1's path) gives casecal.model.catalog."""

    def find_spec(self, fullname, path=None, target=None):
        prefix, _, leaf = fullname.rpartition(".")
        if prefix != __name__ or leaf not in _MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        return importlib.import_module(f"{__name__}.{_MOVED[spec.name.rpartition('.')[2]]}")

    def exec_module(self, module) -> None:
        pass  # the module it stands for is already executed


sys.meta_path.append(_MovedModules())
