"""Files in and out: one module a file kind (cache folders, atomic writes, output folders and
their locks, numeric tables, TUM trajectories)."""
