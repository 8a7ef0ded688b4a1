"""Typed failures of the ``eddie`` commands themselves.

`eddiebot.cli.main` turns these, like every package's typed errors, into one line
``eddie: error: <message>`` on stderr and exit status 2.
"""

from __future__ import annotations

from eddiebot.core.errors import ParameterFileError

__all__ = ["BringUpError", "CliError", "ParamsFileError"]


class CliError(Exception):
    """A command cannot start: the message says what to change, in one line."""


#: A ``--params`` file that is unreadable or not YAML (``FILE:LINE[:COL]: ...``).
ParamsFileError = ParameterFileError


class BringUpError(CliError):
    """A lifecycle manager could not configure and activate its nodes."""
