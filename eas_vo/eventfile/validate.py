"""Row checks of parsed events: pixel inside the sensor, polarity, finite time, time not
going back by more than the tolerance (seconds); the last timestamp carries across blocks."""

from __future__ import annotations

from typing import Callable

import numpy as np

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile.kernels import check_and_pack
from eas_vo.types import EVENT_DTYPE


class Validator:
    """Checks one block of parsed rows at a time, carrying the last timestamp across blocks."""

    def __init__(
        self,
        where: str,
        width: int,
        height: int,
        tolerance_s: float,
        lenient: bool,
        warnings: DataWarnings,
        unit: str = "line",
    ):
        self.where, self.width, self.height, self.unit = where, width, height, unit
        self.tolerance_s, self.lenient, self.warnings = tolerance_s, lenient, warnings
        self.last_t = -np.inf

    def __call__(self, t, x, y, p, line_of: Callable[[int], int], per_second: float = 1.0) -> np.ndarray:
        """EVENT_DTYPE records of the valid rows, in order. Times are t / per_second [s]: t in
        seconds, or integer ticks (per_second 1e6 for microseconds), divided as numpy divides.
        Any integer dtypes, strided views too (the fields of a library's records)."""
        events = np.empty(len(t), EVENT_DTYPE)
        bad, last_t = check_and_pack(
            t, float(per_second), x, y, p, self.last_t, self.width, self.height, self.tolerance_s, events
        )
        if bad < 0:  # the common case: every row is valid
            self.last_t = last_t
            return events
        t = np.asarray(t, dtype=np.float64) if per_second == 1.0 else np.asarray(t) / per_second
        return self._filter(t, np.asarray(x, np.int64), np.asarray(y, np.int64), np.asarray(p, np.int64), line_of)

    def _filter(self, t, x, y, p, line_of) -> np.ndarray:
        """Row-by-row verdicts. Strict: the earliest bad row raises, naming its first problem.
        Lenient: every bad row is dropped and counted once, under its first problem."""
        problems = [
            (~np.isfinite(t), "timestamp is not finite", lambda i: f"t = {t[i]}"),
            (
                (x < 0) | (x >= self.width) | (y < 0) | (y >= self.height),
                f"pixel outside the {self.width}x{self.height} sensor",
                lambda i: f"({x[i]}, {y[i]})",
            ),
            (~np.isin(p, (0, 1, -1)), "polarity not 0/1 (or -1/1)", lambda i: f"p = {p[i]}"),
        ]
        keep = ~np.logical_or.reduce([bad for bad, _, _ in problems])
        # Small steps back in time (within the tolerance) are clamped; larger ones are problems.
        running = np.maximum.accumulate(np.concatenate([[self.last_t], np.where(keep, t, -np.inf)]))[:-1]
        problems.append(
            (
                keep & (t < running - self.tolerance_s),
                "timestamp goes backwards",
                lambda i: f"{t[i]:.9f} after {running[i]:.9f}",
            )
        )
        first_problem = np.full(len(t), -1)
        for k in range(len(problems) - 1, -1, -1):
            first_problem[problems[k][0]] = k
        bad_rows = np.flatnonzero(first_problem >= 0)
        if len(bad_rows) and not self.lenient:
            i = int(bad_rows[0])
            _, what, describe = problems[first_problem[i]]
            raise DataError(self.where, f"{what}: {describe(i)}", line_of(i))
        for k, (_, what, _) in enumerate(problems):
            rows = np.flatnonzero(first_problem == k)
            if len(rows):
                self.warnings.add(self.where, what, f"{self.unit} {line_of(int(rows[0]))}", len(rows))
        keep = first_problem < 0
        t = np.maximum.accumulate(np.concatenate([[self.last_t], t[keep]]))[1:]
        if len(t):
            self.last_t = t[-1]
        events = np.empty(len(t), EVENT_DTYPE)
        events["t"], events["x"], events["y"], events["p"] = t, x[keep], y[keep], p[keep] > 0
        return events
