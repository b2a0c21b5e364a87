"""eas-vo: 3-DoF rotation estimation from event cameras fused with intensity frames.

The Python API (eas_vo.api; docs/python.md) is exported here and imported on first use, so that
`import eas_vo` (which every command does) stays instant: `eas_vo.run(...)`, `eas_vo.open_dataset`,
`eas_vo.frontend`, `eas_vo.evaluate`, `eas_vo.RunResult`.
"""

import logging

__version__ = "0.1.0"
__all__ = ["RunResult", "evaluate", "frontend", "open_dataset", "run"]

# The library logs through the "eas_vo" logger and prints nothing itself: a program using it
# chooses what reaches the user (the command line: eas_vo.logs.to_stderr).
logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str):
    """The API's names, imported from eas_vo.api when first asked for (PEP 562)."""
    if name in __all__:
        from eas_vo import api

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names, the lazy ones among them (for completion in notebooks)."""
    return sorted([*globals(), *__all__])
