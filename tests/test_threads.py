"""The main process keeps one native thread while workers take the cores."""

from __future__ import annotations

import os

import numpy as np
import pytest
from threadpoolctl import threadpool_info

import pcmb.cli
from pcmb.errors import UsageError
from pcmb.run.threads import THREAD_LIMITS, one_thread_here


def _most_threads() -> int:
    np.dot(np.ones((2, 2)), np.ones((2, 2)))  # BLAS loaded
    return max(pool["num_threads"] for pool in threadpool_info())


@pytest.fixture
def several_threads(all_blas_threads):
    if _most_threads() < 2:
        pytest.skip("this process's BLAS runs one thread already (one core or a limit is set)")


def test_one_thread_while_inside_and_everything_restored_after(several_threads, monkeypatch):
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    before = _most_threads()
    with one_thread_here():
        assert _most_threads() == 1
        # Libraries loaded later (scipy's own OpenBLAS) read these when they load.
        assert all(os.environ[name] == "1" for name in THREAD_LIMITS)
    assert _most_threads() == before
    assert os.environ["MKL_NUM_THREADS"] == "3" and "OPENBLAS_NUM_THREADS" not in os.environ


@pytest.mark.parametrize("command", ["run", "validate", "sweep"])
def test_commands_read_their_config_with_one_thread(several_threads, monkeypatch, command):
    seen = {}

    def load_config(path, **options):
        seen["threads"] = _most_threads()
        raise UsageError("stop here")

    monkeypatch.setattr("pcmb.config.schema.load_config", load_config)
    assert (
        pcmb.cli.main([command, "some.yaml", *(["--backend", "inprocess"] * (command == "run"))])
        == 2
    )
    assert seen["threads"] == 1
    assert _most_threads() > 1  # and the whole process again afterwards


@pytest.mark.parametrize(("backend", "bounded"), [("loky", True), ("inprocess", False)])
def test_a_study_keeps_one_thread_while_its_pool_is_open(several_threads, backend, bounded):
    from pcmb.run.backends import open_pool

    with open_pool(backend, 1):
        assert (_most_threads() == 1) == bounded
    assert _most_threads() > 1
