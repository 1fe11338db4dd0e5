"""The cached build shared by the Verilator and Icarus backends
(cosim.backends.build_cache): built once per key, a failed or incomplete build leaves
nothing that looks finished, a concurrent finished build wins the rename."""
from __future__ import annotations

import pytest

from cosim.backends.build_cache import cached_build, publish, temp_dir_beside


def test_built_once_then_reused(tmp_path):
    calls = []

    def build(tmp):
        calls.append(tmp)
        (tmp / "lib.so").write_text("x")
    out, built = cached_build(tmp_path, "k1", "lib.so", build)
    assert built and out == tmp_path / "k1" and (out / "lib.so").read_text() == "x"
    out2, built2 = cached_build(tmp_path, "k1", "lib.so", build)
    assert (out2, built2) == (out, False) and len(calls) == 1
    assert calls[0] != out and not calls[0].exists()        # built aside, then renamed


def test_a_failed_or_incomplete_build_leaves_nothing(tmp_path):
    def fail(tmp):
        (tmp / "half").write_text("x")
        raise RuntimeError("compiler said no")
    with pytest.raises(RuntimeError, match="compiler said no"):
        cached_build(tmp_path, "k2", "lib.so", fail)
    with pytest.raises(RuntimeError, match="did not write lib.so"):
        cached_build(tmp_path, "k2", "lib.so", lambda tmp: (tmp / "other").write_text("x"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k2.lock"]


def test_publish_keeps_a_concurrent_finished_build(tmp_path):
    out = tmp_path / "k3"
    out.mkdir()
    (out / "lib.so").write_text("first")
    (out / "extra").write_text("so the rename fails")
    tmp = temp_dir_beside(out)
    (tmp / "lib.so").write_text("second")
    publish(tmp, out, "lib.so")
    assert (out / "lib.so").read_text() == "first" and not tmp.exists()
    other = tmp_path / "k4"
    other.mkdir()
    (other / "junk").write_text("not a build")
    tmp = temp_dir_beside(other)
    with pytest.raises(OSError):             # not a finished build: the failure is raised
        publish(tmp, other, "lib.so")
