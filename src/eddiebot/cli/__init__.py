"""The ``eddie`` command: one module per sub-command, imported only when used."""

__all__: list[str] = []
