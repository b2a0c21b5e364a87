"""Geometry kernels: rotations and two-view geometry (numpy, scipy, OpenCV; no I/O, no plugins).

- `rotations`: SO(3) helpers: quaternion <-> matrix (the one place), geodesic angle,
  slerp of a ground-truth series, Euler angles for plots.
- `two_view`: the relative rotation of two views from point correspondences: the
  five-point essential matrix, a rotation-only solver, GRIC to choose between them, and a
  plane's homography (for loops).
"""
