"""Experiment design: pose schedules, optimal poses, and calibrate-until-good-enough."""
