"""Text for people: a Markdown table's cells, figures short enough to read, file-name slugs."""

from __future__ import annotations

import math
import re
from pathlib import Path


def markdown_cell(text: str) -> str:
    """`text` as one cell of a Markdown table: each run of white space or control characters
    (a newline too) made one space, and `|` escaped, so the cell can end neither its row nor itself."""
    return re.sub(r"[\s\x00-\x1f\x7f]+", " ", text).strip().replace("|", "\\|")


def figure_text(value: float, decimals: int) -> str:
    """`value` with `decimals` decimals, or in scientific notation (`2.079e+155`) where that
    would print more than six integer digits: every figure short enough to read."""
    if math.isfinite(value) and abs(value) >= 1e6:
        return f"{value:.{max(decimals, 1)}e}"
    return f"{value:.{decimals}f}"


def slug(text: str) -> str:
    """A file-name-safe name for a dataset spec, path or label: its last path component with
    every run of characters other than letters, digits and `._=-` replaced by `-`."""
    return re.sub(r"[^A-Za-z0-9._=-]+", "-", Path(text.rstrip("/")).name or text).strip("-")
