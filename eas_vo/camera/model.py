"""The camera: intrinsics and the lens model (radial-tangential or equidistant), the one place
that projects, undistorts and makes undistortion maps."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np

#: Lens models and the names of their distortion coefficients, in order: `radtan`, OpenCV's
#: radial-tangential (the ECD calib.txt order, ROS's plumb_bob) and `equidistant`, the
#: Kannala-Brandt fisheye model of OpenCV's cv2.fisheye, kalibr and ROS (ORB-SLAM3's
#: KannalaBrandt8). docs/camera_models.md has their equations.
LENS_MODELS = {"radtan": ("k1", "k2", "p1", "p2", "k3"), "equidistant": ("k1", "k2", "k3", "k4")}


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with a lens model (LENS_MODELS): it alone projects, undistorts and makes
    undistortion maps, so a new lens model is a change here only.

    Attributes:
        width, height: sensor size [px].
        K: 3x3 intrinsic matrix [px].
        dist: distortion coefficients in the order of `model` (LENS_MODELS).
        model: `radtan` (default) or `equidistant`.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    model: str = "radtan"

    def __post_init__(self):
        if self.model not in LENS_MODELS:
            raise ValueError(f"unknown lens model {self.model!r}: one of {', '.join(LENS_MODELS)}")
        if len(self.dist) != len(LENS_MODELS[self.model]):
            raise ValueError(
                f"the {self.model} lens model takes {len(LENS_MODELS[self.model])} distortion coefficients, not {len(self.dist)}"
            )

    @classmethod
    def from_calib(cls, values, width: int = 240, height: int = 180) -> "CameraModel":
        """Build from the ECD `calib.txt` values `fx fy cx cy k1 k2 p1 p2 k3`."""
        fx, fy, cx, cy, *dist = [float(v) for v in values]
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        return cls(width, height, K, np.array((dist + [0.0] * 5)[:5]))

    @property
    def focal_px(self) -> float:
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Normalised image coordinates (N, 2) or rays in the camera frame (N, 3) -> distorted
        pixel coordinates (N, 2) [px]. Rays need z > 0 for `radtan`; `equidistant` maps every
        direction (it distorts the angle to the optical axis, not its tangent; the backward axis
        lands on the principal point)."""
        from eas_vo.camera.lens import project_points

        p = np.asarray(points, dtype=np.float64)
        p = np.ascontiguousarray(p.reshape(-1, p.shape[-1]))
        out = np.empty((len(p), 2))
        project_points(
            p, np.asarray(self.K, np.float64), np.asarray(self.dist, np.float64), self.model == "equidistant", out
        )
        return out

    @property
    def distorted(self) -> bool:
        """Whether rays do not project as through a pinhole: any `radtan` coefficient not zero, or
        the `equidistant` model (a fisheye even with its coefficients all zero)."""
        return self.model != "radtan" or bool(np.any(np.asarray(self.dist) != 0))

    @functools.cached_property
    def pixel_rays(self) -> np.ndarray:
        """(height * width, 3) rays (z = 1) of the sensor's pixels, row by row (undistorted once)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        rays = self._rays(np.column_stack([u.ravel(), v.ravel()]))
        rays.flags.writeable = False  # shared by every use of this camera
        return rays

    def rotated_pixels(self, R_to_from: np.ndarray, pts_px: np.ndarray) -> np.ndarray:
        """Where pixels pts_px (N, 2) [px] of a view lie in a view rotated from it (ray_to =
        R_to_from @ ray_from), through the lens model both ways: (N, 2) [px]; -1 for rays
        behind a `radtan` camera."""
        return self._rays_to_pixels(self._rays(pts_px) @ np.asarray(R_to_from, np.float64).T)

    def rotation_maps(self, R_from_to: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (x, y), each (height, width) float32 [px]: for every pixel of a view
        rotated from another (ray_from = R_from_to @ ray_to), where it lies in that other view's
        image, through the lens model; -1 for rays behind a `radtan` camera (cv2.remap's border).
        A lens model that folds back beyond its calibrated field of view maps what it gives there."""
        px = self._rays_to_pixels(self.pixel_rays @ np.asarray(R_from_to, np.float64).T).astype(np.float32)
        return px[:, 0].reshape(self.height, self.width), px[:, 1].reshape(self.height, self.width)

    def _rays(self, pts_px: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) [px] -> their rays (N, 3) in the camera frame, z = 1."""
        rays = np.ones((len(pts_px), 3))
        rays[:, :2] = self.undistort(pts_px)
        return rays

    def _rays_to_pixels(self, rays: np.ndarray) -> np.ndarray:
        """project(rays), -1 for rays `radtan` cannot project (z <= 0: behind the camera)."""
        px = self.project(rays)
        if self.model == "radtan":
            px[rays[:, 2] <= 0] = -1.0
        return px

    def undistort(self, pts_px: np.ndarray) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) [px] -> normalised image coordinates (N, 2)."""
        pts = np.ascontiguousarray(pts_px, dtype=np.float64).reshape(-1, 1, 2)
        if len(pts) == 0:
            return np.empty((0, 2))
        if self.model == "equidistant":
            return cv2.fisheye.undistortPoints(pts, self.K, self.dist).reshape(-1, 2)
        return cv2.undistortPoints(pts, self.K, self.dist).reshape(-1, 2)

    def undistort_maps(self, K_new: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (x, y), each (height, width) float32 [px]: for every pixel of the
        undistorted pinhole view with intrinsics K_new (default K), where it lies in this
        camera's image."""
        K_new = self.K if K_new is None else np.asarray(K_new, dtype=np.float64)
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(K_new).T
        px = self.project(rays).astype(np.float32)
        return px[:, 0].reshape(u.shape), px[:, 1].reshape(u.shape)

    def fold(self) -> tuple[float, float, float] | None:
        """Where the lens' radial projection stops growing inside the sensor, or None when it
        grows out to the sensor's farthest corner (the pixel edges, (0, 0) to (width, height)):
        (its radius from the principal point [px, focal_px], the ray's angle to the optical axis
        there [rad], the farthest corner's radius [px]). Beyond such a fold two rays land on one
        pixel and undistortion inverts the wrong branch. `equidistant` maps rays up to 180 deg: a
        sensor reaching past that radius folds there. The tangential terms of `radtan` (p1 p2)
        are left out: the radial part decides whether the projection folds."""
        from eas_vo.camera.lens import first_fold

        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        corner = max(np.hypot((u - cx) / fx, (v - cy) / fy) for u in (0, self.width) for v in (0, self.height))
        if self.model == "equidistant":
            coefficients, theta = self.dist, lambda x: x
            x = first_fold(coefficients, np.pi)
        else:
            coefficients, theta = (self.dist[0], self.dist[1], self.dist[4]), np.arctan
            x = first_fold(coefficients, np.inf)
        radius = x * (1.0 + sum(c * x ** (2 * n + 2) for n, c in enumerate(coefficients))) if np.isfinite(x) else np.inf
        if radius >= corner:
            return None
        return float(radius * self.focal_px), float(theta(x)), float(corner * self.focal_px)

    def calib_values(self) -> list[float]:
        """`fx fy cx cy` and the distortion coefficients in the order of `model`."""
        K = self.K
        return [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *self.dist]
