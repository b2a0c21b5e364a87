"""The camera: `CameraModel` (intrinsics, lens, projection and undistortion) and the lens
models' compiled projection."""

from eas_vo.camera.model import LENS_MODELS, CameraModel

__all__ = ["LENS_MODELS", "CameraModel"]
