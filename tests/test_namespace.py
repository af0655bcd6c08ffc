"""casecal's namespace: the public names only, loaded lazily, and no import shim for
module paths no release had."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import casecal as cc

# docs/design.md, "Public API (outside scripts rely on these names)", and README.md
DOCUMENTED = {
    "load_robot",
    "poses",
    "simulate",
    "identify",
    "observability",
    "save_robot",
    "compensate",
    "compensate_program",
    "compare_models",
    "CameraSetup",
    "Intrinsics",
    "Checkerboard",
    "PixelMeasurements",
    "CalibrationError",
    "CalibrationWarning",
    "Calibration",
    "calibrate_until",
    "read_csv",
    "write_csv",
    "robots",
    "validate",
}


def test_dir_lists_the_public_names_and_nothing_else():
    names = set(dir(cc))
    assert DOCUMENTED <= names
    assert names == {*cc.__all__, "__version__"}
    for helper in ("sys", "importlib", "annotations", "_importlib", "_PUBLIC"):
        assert helper not in names


def test_every_public_name_loads():
    for name in cc.__all__:
        assert getattr(cc, name) is not None
    assert cc.compensate_program.__module__ == "casecal.programs"


def test_unknown_names_and_old_module_paths_are_gone():
    with pytest.raises(AttributeError, match="no attribute 'parameters'"):
        cc.parameters  # noqa: B018 (casecal 0.1's flat path: never released)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("casecal.catalog")


def test_import_leaks_no_modules_into_the_namespace():
    # a fresh interpreter: nothing imported as a side effect shows in dir()
    code = "import casecal; print(sorted(set(dir(casecal)) - set(casecal.__all__)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['__version__']"
