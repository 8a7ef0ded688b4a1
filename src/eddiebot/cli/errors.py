"""Typed failures of the ``eddie`` commands themselves.

`eddiebot.cli.main` turns these, like every package's typed errors, into one line
``eddie: error: <message>`` on stderr and exit status 2.
"""

from __future__ import annotations

__all__ = ["BringUpError", "CliError", "ParamsFileError"]


class CliError(Exception):
    """A command cannot start: the message says what to change, in one line."""


class ParamsFileError(CliError, ValueError):
    """A ``--params`` file is unreadable, not YAML, or sets a parameter no node has; the
    message names the file and the line (``FILE:LINE: ...``)."""


class BringUpError(CliError):
    """A lifecycle manager could not configure and activate its nodes."""
