"""Importing the toolkit leaves the process's environment as it was; an executable installed
only into the Python environment's ``bin`` directory is still found, and a tool launched with
:func:`cosim.core.executables.tool_env` finds it too."""
from __future__ import annotations

import json
import os
import subprocess
import sys

from cosim.core.executables import find_executable, tool_env, tool_path


def test_importing_cosim_changes_no_environment_variable():
    code = ("import json, os; before = dict(os.environ); import cosim, cosim.cli; "
            "print(json.dumps([before, dict(os.environ)]))")
    env = {**os.environ, "PATH": "/usr/bin:/bin"}     # the interpreter's bin not on it
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       timeout=120, check=True)
    before, after = json.loads(p.stdout)
    assert before["PATH"] == "/usr/bin:/bin"
    assert after == before


def test_a_tool_only_beside_the_interpreter_is_found_and_launched_with_it(tmp_path,
                                                                           monkeypatch):
    env_bin = tmp_path / "venv" / "bin"
    env_bin.mkdir(parents=True)
    tool = env_bin / "kfnav-probe-tool"
    tool.write_text("#!/bin/sh\necho probe\n")
    tool.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(env_bin / "python"))
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    assert find_executable("kfnav-probe-tool") == str(tool)
    assert find_executable("kfnav-no-such-tool") is None
    assert tool_path() == f"/usr/bin:/bin{os.pathsep}{env_bin}"
    out = subprocess.run(["sh", "-c", "kfnav-probe-tool"], env=tool_env(), capture_output=True,
                         text=True, check=True).stdout
    assert out == "probe\n"
    assert os.environ["PATH"] == "/usr/bin:/bin"
    # already on PATH: not added twice
    monkeypatch.setenv("PATH", f"{env_bin}{os.pathsep}/bin")
    assert tool_path() == f"{env_bin}{os.pathsep}/bin"
