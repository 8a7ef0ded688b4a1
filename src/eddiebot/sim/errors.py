"""Typed failures of the simulator cores."""

from __future__ import annotations


class SimError(Exception):
    """Base class of every simulator failure."""


class WorldFileError(SimError, ValueError):
    """A world file that cannot be used. The message names file, line, object and field:
    ``office.yaml:42: boxes[3] 'desk': field 'size': expected [x, y] numbers``."""

    def __init__(self, file: str, line: int | None, obj: str, field: str | None, problem: str):
        self.file, self.line, self.obj, self.field, self.problem = file, line, obj, field, problem
        where = f"{file}:{line}" if line is not None else file
        what = f"{obj}: field '{field}'" if field else obj
        super().__init__(f"{where}: {what}: {problem}")


class UnknownWorldError(SimError, KeyError):
    """A world name that is neither a built-in world nor a readable file."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown world"
