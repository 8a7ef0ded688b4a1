"""Reading a ``--params`` file so that its errors name file and line: see
:func:`eddiebot.core.parameters.load_params_file`. Keys that no Nav2 server reads are named by
:func:`eddiebot.nav.nodes.params_audit.audit_nav2_params`, as ``eddie nav`` does."""

from __future__ import annotations

from eddiebot.core.parameters import load_params_file

__all__ = ["load_params_file"]
