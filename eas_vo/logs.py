"""The library's messages on stderr, as the command line shows them: each record of the package
logger "eas_vo" as one line, "eas-vo: MESSAGE" at INFO (progress notices: fetching, simulating,
copying) and "eas-vo: warning: MESSAGE" at WARNING and above. The library itself only logs
(eas_vo/__init__.py gives the logger a NullHandler); a program using it decides what is shown."""

from __future__ import annotations

import logging
import sys

LOGGER = "eas_vo"


class _Stderr(logging.StreamHandler):
    """A handler writing to whatever sys.stderr is when a record comes (as logging.lastResort
    does), so that a stderr replaced later (a redirect, pytest's capture) gets the lines."""

    def __init__(self) -> None:
        logging.Handler.__init__(self)

    @property
    def stream(self):
        return sys.stderr


class _Format(logging.Formatter):
    """ "eas-vo: " before every message, "warning: " after it from WARNING up."""

    def format(self, record: logging.LogRecord) -> str:
        prefix = "eas-vo: warning: " if record.levelno >= logging.WARNING else "eas-vo: "
        return prefix + super().format(record)


def to_stderr() -> None:
    """Print the "eas_vo" logger's records from INFO up on stderr, one line each; calling it
    again adds no second handler."""
    logger = logging.getLogger(LOGGER)
    if not any(isinstance(handler, _Stderr) for handler in logger.handlers):
        handler = _Stderr()
        handler.setFormatter(_Format("%(message)s"))
        logger.addHandler(handler)
    logger.setLevel(logging.INFO)
