"""User-facing errors: the CLI prints them as one line, without a traceback."""


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
