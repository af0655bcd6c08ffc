"""xacro files expanded to URDF text, by xacrodoc or else by the xacro package."""

from __future__ import annotations

from pathlib import Path

from ..errors import CalibrationError


def expand_xacro(path: Path, packages: dict[str, str]) -> str:
    """The URDF text of a xacro file, by xacrodoc (which resolves ROS packages without a
    ROS install), else by the xacro package."""
    if not path.is_file():
        raise CalibrationError(f"{path}: no such file")
    try:
        from xacrodoc import XacroDoc
        from xacrodoc import packages as known

        def expand() -> str:
            known.walk_up_from(str(path))
            known.update_package_cache(dict(packages))
            return XacroDoc.from_file(str(path)).to_urdf_string()

    except ImportError:
        try:
            import xacro
        except ImportError:
            raise CalibrationError(
                f"{path}: a .xacro file needs the urdf extra: pip install 'casecal[urdf]'"
            ) from None

        def expand() -> str:
            return xacro.process_file(str(path)).toxml()

    try:
        return expand()
    except Exception as exc:  # xacro raises its own and many builtin types
        detail = " ".join(str(exc).split())
        raise CalibrationError(
            f"{path}: xacro could not expand it ({detail}); name the ROS packages it "
            "finds with --package NAME=PATH (command line) or packages={name: folder} "
            "(Python: load_robot), or run 'xacro FILE > robot.urdf' in its workspace and "
            "load the .urdf"
        ) from None
