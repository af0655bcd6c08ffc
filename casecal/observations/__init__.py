"""Observation models beyond a tracker's points: camera pixels of a calibration target.

- `casecal.observations.camera`: `Intrinsics`, `project` and its exact derivatives
  (OpenCV's pinhole + Brown–Conrady model);
- `casecal.observations.target`: `Checkerboard` and its corners' order;
- `casecal.observations.simulate`: pixels of a board seen eye-in-hand or eye-to-hand, and
  random views that see the whole board;
- `casecal.observations.residuals`: the pixel residuals of a robot and their Jacobian;
- `casecal.observations.pixels`: `PixelMeasurements`, what `casecal.identify` takes of a
  camera, and `simulate_camera`;
- `casecal.observations.rig`: the camera and the robot as one robot (the fit's view of them).

The fit itself is the one fitting path's (`casecal.identification.camera_fit`,
`casecal.identification.pixel_problem`).
"""
