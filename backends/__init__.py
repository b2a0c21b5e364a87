"""Backend plugins (relative -> absolute rotations); installed as `eas_vo.backends`."""
