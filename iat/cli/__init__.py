"""The ``iat`` command: ``commands`` parses and dispatches, ``args`` parses option values."""

from iat.cli.commands import main

__all__ = ["main"]
