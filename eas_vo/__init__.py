"""eas-vo: 3-DoF rotation estimation from event cameras fused with intensity frames."""

import logging

__version__ = "0.1.0"

# The library logs through the "eas_vo" logger and prints nothing itself: a program using it
# chooses what reaches the user (the command line: eas_vo.logs.to_stderr).
logging.getLogger(__name__).addHandler(logging.NullHandler())
