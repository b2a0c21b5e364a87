"""Geometry kernels: rotations and two-view geometry (numpy, scipy, OpenCV; no I/O, no plugins).

- `rotations`: SO(3) helpers: quaternion <-> matrix (the one place), geodesic angle,
  slerp of a ground-truth series, Euler angles for plots.
- `two_view`: the relative rotation of two views from point correspondences: the
  five-point essential matrix, a rotation-only solver, GRIC to choose between them, and a
  plane's homography (for loops).
- `covariance`: the covariance of a relative rotation measured from bearing correspondences.
- `uncertainty`: the uncertainty of absolute orientations: the chain's first-order
  propagation of its steps' covariances, sigmas per camera axis or per Euler angle.
"""
