"""The compiling helper of a first run (asrbf_mesh._warm)."""

from __future__ import annotations

import contextlib
import subprocess
import sys

import pytest

from asrbf_mesh import _warm


def test_the_helper_calls_what_a_fit_calls_after_learning() -> None:
    # in-process here (the kernels are cached by then): the helper's calls must stay valid
    _warm.compile_after_learning()


def test_no_helper_on_a_warm_cache_or_for_commands_that_do_not_learn(monkeypatch) -> None:
    def refuse(*a, **k):
        raise AssertionError("no helper expected")

    monkeypatch.setattr(subprocess, "Popen", refuse)
    monkeypatch.setattr(_warm, "_learning_kernel_cached", lambda: True)
    with _warm.alongside("fit"):
        pass
    monkeypatch.setattr(_warm, "_learning_kernel_cached", lambda: False)
    for command in ("info", "metro", "reconstruct", None):
        with _warm.alongside(command):
            pass
    monkeypatch.setenv("ASRBF_NO_WARM", "1")
    with _warm.alongside("fit"):
        pass


@pytest.mark.parametrize("fail", [False, True])
def test_the_helper_never_outlives_the_command(monkeypatch, fail: bool) -> None:
    started = []
    real = subprocess.Popen

    def sleeper(args, **kw):
        assert args[1:] == ["-m", "asrbf_mesh._warm"]
        started.append(real([sys.executable, "-c", "import time; time.sleep(60)"], **kw))
        return started[-1]

    monkeypatch.delenv("ASRBF_NO_WARM", raising=False)
    monkeypatch.setattr(_warm, "_learning_kernel_cached", lambda: False)
    monkeypatch.setattr(subprocess, "Popen", sleeper)
    with pytest.raises(RuntimeError) if fail else contextlib.nullcontext():
        with _warm.alongside("demo"):
            assert started and started[0].poll() is None  # running beside the command
            if fail:
                raise RuntimeError("the command failed")
    assert started[0].poll() is not None  # killed and reaped when the command ended

