"""The error every layer raises for bad input, low enough for any module to import."""


class ConfigError(ValueError):
    """A bad training input; the message is one line naming the key, its value and what is allowed."""
