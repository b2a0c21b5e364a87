"""User-facing errors (the CLI prints them as one line, without a traceback) and the
warnings of data problems tolerated under `--lenient`."""

from __future__ import annotations

import json
import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field


class EasVoError(Exception):
    """A problem with the user's input (data, config, arguments), not a bug."""


class DataError(EasVoError):
    """Malformed or missing input data; the message names the file and line."""

    def __init__(self, path, message: str, line: int | None = None):
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {message}")
        self.path = path
        self.line = line


class ConfigError(EasVoError):
    """An invalid configuration key or value."""


class UsageError(EasVoError):
    """Command-line options that cannot go together or cannot be read (exit status 2, as for
    argparse's own usage errors; data and configuration errors exit with 1)."""


@dataclass
class DataWarnings:
    """Problems tolerated under `--lenient`, counted per file and kind, with the first place."""

    counts: dict = field(default_factory=dict)
    first: dict = field(default_factory=dict)

    def add(self, where: str, what: str, first_at, n: int = 1) -> None:
        key = (where, what)
        self.counts[key] = self.counts.get(key, 0) + n
        self.first.setdefault(key, first_at)

    def merge(self, other: "DataWarnings") -> None:
        for (where, what), n in other.counts.items():
            self.add(where, what, other.first[(where, what)], n)

    def lines(self) -> list[str]:
        return [
            f"{where}: {n} dropped: {what} (first at {self.first[(where, what)]})"
            for (where, what), n in self.counts.items()
        ]

    def to_json(self) -> str:
        return json.dumps([[w, k, self.first[(w, k)], n] for (w, k), n in self.counts.items()])

    @classmethod
    def from_json(cls, text: str) -> "DataWarnings":
        out = cls()
        for where, what, first_at, n in json.loads(text):
            out.add(where, what, first_at, n)
        return out


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM (`sigterm`), with a note of what was saved before stopping (`kept`)."""

    def __init__(self, kept: str = "", sigterm: bool = False):
        super().__init__(kept)
        self.kept = kept
        self.sigterm = sigterm

    @classmethod
    def keeping(cls, cause: KeyboardInterrupt, kept: str) -> "Interrupted":
        """The interrupt `cause`, re-raised once `kept` was saved."""
        return cls(kept, sigterm=isinstance(cause, Interrupted) and cause.sigterm)


@contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises Interrupted(sigterm=True), handled like Ctrl-C (main
    thread only; elsewhere a no-op). The previous handler is restored after. Used by the CLI
    and by each compare worker process, whatever the process start method."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Interrupted(sigterm=True)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
