"""eas-vo: 3-DoF rotation estimation from event cameras fused with intensity frames."""

__version__ = "0.1.0"
