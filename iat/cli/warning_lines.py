"""Warnings as one line each on stderr: ``iat CMD: warning: ...`` (IATWarnings and the ``iat``
loggers' warnings), printed above a progress bar if one is drawn."""

from __future__ import annotations

import logging
import sys
import warnings

from iat.errors import IATWarning


def print_warning(command: str, text: str) -> None:
    from tqdm import tqdm

    line = " ".join(str(text).split())
    tqdm.write(f"iat {command}: warning: {line}", file=sys.stderr)  # above a progress bar, if any


def warning_printer(command: str):
    """A :func:`warnings.showwarning` that prints an IATWarning as one line on stderr."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, IATWarning):
            return default(message, category, filename, lineno, file, line)
        print_warning(command, message)

    return show


class WarningLines(logging.Handler):
    """Prints the ``iat`` loggers' warnings as ``iat CMD: warning: ...`` lines on stderr."""

    def __init__(self, command: str):
        super().__init__(logging.WARNING)
        self.command = command

    def emit(self, record: logging.LogRecord) -> None:
        print_warning(self.command, record.getMessage())
