"""casecal: kinematic calibration of serial robot arms.

A robot is a CasADi graph of its kinematic chain, with exact Jacobians of the end-effector
position with respect to every parameter. See DESIGN.md for the data flow and README.md for
the commands.

The public names below are loaded on first use (PEP 562), so ``import casecal`` and the
``casecal`` command start at once and Ctrl-C is answered from the first moment.
"""

import importlib as _importlib

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
    "compensate_program": "programs",
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

__all__ = sorted([*_PUBLIC, *_MODULES])


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(_importlib.import_module(f"{__name__}.{_PUBLIC[name]}"), name)
    elif name in _MODULES:
        value = _importlib.import_module(f"{__name__}.{_MODULES[name]}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The public names (`__all__`) and the version: no imports or helpers."""
    return sorted([*__all__, "__version__"])
