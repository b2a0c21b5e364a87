"""The library's log records on stderr as the command line prints them: "eas-vo: " at INFO,
"eas-vo: warning: " from WARNING up, one handler however often it is installed, writing to
whatever stderr is at the time; without it the library prints nothing."""

import logging

import pytest

from eas_vo import logs


@pytest.fixture
def package_logger():
    """The "eas_vo" logger, its handlers and level put back after the test."""
    logger = logging.getLogger("eas_vo")
    handlers, level = list(logger.handlers), logger.level
    yield logger
    logger.handlers[:] = handlers
    logger.setLevel(level)


def test_records_become_one_line_each_with_the_warning_word_from_warning_up(package_logger, capsys):
    logs.to_stderr()
    logs.to_stderr()
    log = logging.getLogger("eas_vo.datasets.synthetic")
    log.debug("not shown")
    log.info("simulating synthetic:default (10 s) into /tmp/x (once)")
    log.warning("the event cache folder /tmp/c cannot be written")
    log.error("worse")
    assert capsys.readouterr().err == (
        "eas-vo: simulating synthetic:default (10 s) into /tmp/x (once)\n"
        "eas-vo: warning: the event cache folder /tmp/c cannot be written\n"
        "eas-vo: warning: worse\n"
    )


def test_without_the_handler_the_library_prints_nothing(package_logger, capsys):
    package_logger.handlers[:] = [h for h in package_logger.handlers if isinstance(h, logging.NullHandler)]
    package_logger.setLevel(logging.NOTSET)
    logging.getLogger("eas_vo.eventfile.cache").warning("the event cache folder /tmp/c cannot be written")
    assert capsys.readouterr().err == ""
