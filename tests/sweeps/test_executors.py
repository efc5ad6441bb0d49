"""The same sweep on every executor gives byte-identical result rows: serial (this
process), a local pool of two spawned workers, and a Dask LocalCluster of two single-thread
worker processes on 127.0.0.1. Timing and provenance (wall times, host, pid) differ by
design and are left out of the comparison; everything a trial computes is in `result`."""

from __future__ import annotations

import os
import sys
from typing import Any

import pytest

from omnisort_hw.errors import MissingExtraError
from omnisort_hw.sweeps.executors import DaskExecutor, PoolExecutor, make_executor
from omnisort_hw.sweeps.runner import result_rows, run_sweep
from omnisort_hw.sweeps.trial import canonical_json

pytestmark = pytest.mark.timeout(240)


def _differences(a: Any, b: Any, path: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        return [
            d
            for k in sorted(set(a) | set(b))
            for d in _differences(a.get(k), b.get(k), f"{path}.{k}")
        ]
    return [] if a == b else [f"{path}: {a!r:.80} != {b!r:.80}"]


def _same_results(rows: list[dict[str, Any]], reference: list[dict[str, Any]]) -> None:
    assert [r["key"] for r in rows] == [r["key"] for r in reference]
    got = [canonical_json(r["result"]) for r in rows]
    want = [canonical_json(r["result"]) for r in reference]
    if got != want:  # name the entries that differ
        diffs = [
            d
            for r, s in zip(rows, reference, strict=True)
            for d in _differences(r["result"], s["result"])
        ]
        pytest.fail("results differ: " + "; ".join(diffs))


def test_the_reference_rows_hold_measurements(serial_rows: list[dict[str, Any]]) -> None:
    """The comparison below is about numbers, not only error strings."""
    single = [r["result"]["single"] for r in serial_rows]
    assert all(isinstance(s.get("laser_points"), int) for s in single), single
    assert any(s["laser_points"] > 0 for s in single)
    assert all(r["provenance"]["pid"] == os.getpid() for r in serial_rows)


def test_the_pool_gives_the_same_rows(
    small_trials: list[Any], serial_rows: list[dict[str, Any]]
) -> None:
    with PoolExecutor(workers=2, timeout_s=180) as ex:
        run = run_sweep(small_trials, executor=ex)
    _same_results(run.rows, serial_rows)
    pids = {r["provenance"]["pid"] for r in run.rows}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    for row in run.rows:  # one BLAS thread per worker
        assert set(row["provenance"]["blas_threads"].values()) == {"1"}


def test_a_local_dask_cluster_gives_the_same_rows(
    small_trials: list[Any], serial_rows: list[dict[str, Any]]
) -> None:
    pytest.importorskip("distributed")
    with DaskExecutor(workers=2, timeout_s=180, connect_timeout_s=60) as ex:
        assert ex._client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert ex.workers == 2
        run = run_sweep(small_trials, executor=ex)
    _same_results(run.rows, serial_rows)
    assert result_rows(run) == [r["result"] for r in serial_rows]
    pids = {r["provenance"]["pid"] for r in run.rows}
    assert os.getpid() not in pids
    for row in run.rows:  # the nanny's default environment: one BLAS thread
        assert row["provenance"]["blas_threads"]["OMP_NUM_THREADS"] == "1"


def test_without_dask_the_error_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    with pytest.raises(MissingExtraError, match=r"omnisort-hw\[dask\]"):
        make_executor("dask")


def _tiny(config: Any, seed: int) -> Any:
    from omnisort_hw.sweeps.trial import TrialOutput

    return TrialOutput({"sum": config["a"] + seed})


def test_a_scheduler_address_is_used_and_workers_must_match_the_client(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """`--scheduler ADDRESS` connects to a running cluster (here one in this process, on
    loopback) and refuses workers whose package versions differ from the client's."""
    distributed = pytest.importorskip("distributed")
    import threading

    from omnisort_hw.errors import InputError
    from omnisort_hw.sweeps import provenance
    from omnisort_hw.sweeps import trial as trial_mod
    from omnisort_hw.sweeps.trial import Trial

    monkeypatch.setitem(trial_mod.EXPERIMENTS, "tiny", f"{__name__}:_tiny")
    with distributed.LocalCluster(
        n_workers=1,
        processes=False,
        threads_per_worker=1,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        timeout=60,
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        trials = [Trial("tiny", {"a": a}, 5) for a in range(3)]
        with make_executor("dask", scheduler=address, timeout_s=60) as ex:
            run = run_sweep(trials, executor=ex)
        assert [r["result"]["sum"] for r in run.rows] == [5, 6, 7]
        # A worker with other versions: the client's thread and the worker's differ here.
        monkeypatch.setattr(
            provenance,
            "package_versions",
            lambda: {"numpy": f"0.0+{threading.current_thread().name}"},
        )
        with pytest.raises(InputError, match="runs other versions than this client"):
            make_executor("dask", scheduler=address, timeout_s=60)
