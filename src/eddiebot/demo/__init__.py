"""The ``make demo`` mission: stages that each exercise the real stack and report numbers."""

__all__: list[str] = []
