"""Parameter sweeps: grids of robots × schedules × pose counts × noise × methods × trials,
run by local processes or dask, into tidy DataFrames (the report draws them)."""
