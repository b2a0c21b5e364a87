"""Accuracy against ground truth: the paper's Eq. 3 APE, the motion errors (angular velocity,
RPE), the ground truth's time offset, and the trajectory APE of 6-DoF estimates (Umeyama)."""
