"""Hand-held-like 6-DoF motion: mostly rotation, small translation, speed growing over time."""

from __future__ import annotations

import numpy as np

from eas_vo.geometry.rotations import rotvec_to_matrix

# (amplitude [rad], frequency [Hz]) per rotation axis (camera x = pitch, y = yaw, z = roll).
ROTATION_TERMS = (
    ((0.12, 0.30), (0.05, 0.80), (0.004, 2.7)),
    ((0.25, 0.25), (0.10, 0.60), (0.004, 3.1)),
    ((0.06, 0.35), (0.03, 0.90), (0.003, 2.3)),
)
# (amplitude [m], frequency [Hz]) per translation axis.
TRANSLATION_TERMS = (((0.04, 0.20), (0.01, 0.7)), ((0.03, 0.25), (0.01, 0.9)), ((0.03, 0.15), (0.01, 0.5)))


class HandHeldMotion:
    """Smooth random motion; frequencies (hence speeds) grow linearly by `speed_growth` over
    `duration_s`, all scaled by `speed` (the same path, travelled `speed` times as fast); the
    translation is `translation_scale` times TRANSLATION_TERMS' (the same path, its positions
    scaled about the origin).

    Poses are camera-to-world: R_w_c(t) = R_w_c0 Exp(rotvec(t)), p_w_c(t).
    """

    def __init__(
        self,
        rng: np.random.Generator,
        duration_s: float,
        speed_growth: float = 1.5,
        speed: float = 1.0,
        translation_scale: float = 1.0,
    ):
        self.duration_s = duration_s
        self.speed_growth = speed_growth
        self.speed = speed
        self.translation_scale = translation_scale
        self.rot_phase = rng.uniform(0, 2 * np.pi, (3, len(ROTATION_TERMS[0])))
        self.trans_phase = rng.uniform(0, 2 * np.pi, (3, len(TRANSLATION_TERMS[0])))
        self.R_w_c0 = rotvec_to_matrix(np.array([0.05, 0.15, -0.03]))

    def _warped_time(self, t: np.ndarray) -> np.ndarray:
        """phi(t) = v (t + g t^2 / (2 T)): instantaneous frequency grows by factor (1 + g) over T,
        times the speed v."""
        return self.speed * (t + self.speed_growth * t**2 / (2.0 * self.duration_s))

    @staticmethod
    def _sines(phi: np.ndarray, terms, phases) -> np.ndarray:
        out = np.zeros((len(phi), 3))
        for axis in range(3):
            for (amp, freq), phase in zip(terms[axis], phases[axis]):
                out[:, axis] += amp * np.sin(2 * np.pi * freq * phi + phase)
        return out

    def pose(self, t) -> tuple[np.ndarray, np.ndarray]:
        """(R_w_c (N, 3, 3), p_w_c (N, 3) [m]) at times `t` [s]."""
        phi = self._warped_time(np.atleast_1d(np.asarray(t, dtype=float)))
        rotvec = self._sines(phi, ROTATION_TERMS, self.rot_phase)
        rotvec -= self._sines(np.zeros(1), ROTATION_TERMS, self.rot_phase)  # start at R_w_c0
        return self.R_w_c0 @ rotvec_to_matrix(rotvec), self.translation_scale * self._sines(
            phi, TRANSLATION_TERMS, self.trans_phase
        )

    def angular_velocity(self, t, h: float = 1e-4) -> np.ndarray:
        """Body angular velocity omega_c [rad/s] (N, 3) by central differences of R_w_c."""
        from scipy.spatial.transform import Rotation

        R0, _ = self.pose(np.asarray(t) - h)
        R1, _ = self.pose(np.asarray(t) + h)
        return Rotation.from_matrix(np.swapaxes(R0, 1, 2) @ R1).as_rotvec() / (2 * h)

    def acceleration(self, t, h: float = 1e-3) -> np.ndarray:
        """World acceleration [m/s^2] (N, 3) by central differences of p_w_c."""
        t = np.asarray(t)
        _, p0 = self.pose(t - h)
        _, p1 = self.pose(t)
        _, p2 = self.pose(t + h)
        return (p0 - 2 * p1 + p2) / h**2


class ConstantMotion:
    """A constant body angular velocity omega_c [rad/s] and a constant world velocity [m/s]:
    R_w_c(t) = R_w_c0 Exp(omega_c t), p_w_c(t) = p_w_c0 + velocity t (known-answer motion)."""

    def __init__(self, omega_c, velocity_w=(0.0, 0.0, 0.0), R_w_c0=None, p_w_c0=(0.0, 0.0, 0.0)):
        self.omega_c = np.asarray(omega_c, float)
        self.velocity_w = np.asarray(velocity_w, float)
        self.R_w_c0 = np.eye(3) if R_w_c0 is None else np.asarray(R_w_c0, float)
        self.p_w_c0 = np.asarray(p_w_c0, float)

    def pose(self, t) -> tuple[np.ndarray, np.ndarray]:
        """(R_w_c (N, 3, 3), p_w_c (N, 3) [m]) at times `t` [s]."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return self.R_w_c0 @ rotvec_to_matrix(t[:, None] * self.omega_c), self.p_w_c0 + t[:, None] * self.velocity_w

    def angular_velocity(self, t) -> np.ndarray:
        """omega_c [rad/s] (N, 3) at times `t`."""
        return np.tile(self.omega_c, (len(np.atleast_1d(t)), 1))
