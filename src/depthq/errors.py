"""The project's error types: the CLI maps them to clear messages and exit statuses."""


class ConfigError(ValueError):
    """Bad configuration or input value; the message names the value. CLI exit status 2."""


class DataError(RuntimeError):
    """A stored file is missing, truncated, corrupted or does not match its manifest. Exit status 1."""
