"""Experiments over many runs: a grid of runs and its results (compare), the paper's tables on
its own data (reproduce), its Fig. 1 gallery, and the scoring of other tools' trajectories."""
