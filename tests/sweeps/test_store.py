"""The sweep's bookkeeping without the simulator: content keys, the rows file after a kill
(torn last line), someone else's file, result/timing split, and resuming after a failure."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from omnisort_hw.errors import InputError
from omnisort_hw.sweeps import trial as trial_mod
from omnisort_hw.sweeps.runner import run_sweep
from omnisort_hw.sweeps.store import SweepStore
from omnisort_hw.sweeps.trial import Trial, TrialOutput, merge_paths, split_paths


def test_key_is_a_content_hash() -> None:
    a = Trial("lighting", {"width": 256, "frames": 1}, 3)
    assert a.key == Trial("lighting", {"frames": 1, "width": 256}, 3).key  # order-free
    assert a.key != Trial("lighting", {"frames": 1, "width": 256}, 4).key
    assert a.key != Trial("lighting", {"frames": 1, "width": 256.5}, 3).key
    assert a.key != Trial("drift", {"frames": 1, "width": 256}, 3).key


def _row(t: Trial, value: float) -> dict[str, Any]:
    return {**t.to_dict(), "result": {"v": value}, "timing": {}, "provenance": {}}


def test_a_torn_last_line_is_cut_and_its_trial_runs_again(tmp_path: Path) -> None:
    trials = [Trial("x", {"i": i}, 0) for i in range(3)]
    store = SweepStore(tmp_path)
    assert store.open(trials, {}) == {}
    store.append(_row(trials[0], 0.1))
    store.append(_row(trials[1], 0.2))
    whole = store.rows_path.read_bytes()
    with store.rows_path.open("ab") as f:  # what a kill in the middle of a write leaves
        f.write(json.dumps(_row(trials[2], 0.3)).encode()[:17])
    done = SweepStore(tmp_path).open(trials, {})
    assert sorted(done) == sorted([trials[0].key, trials[1].key])
    assert store.rows_path.read_bytes() == whole


def test_a_bad_line_inside_or_another_sweep_is_an_error(tmp_path: Path) -> None:
    trials = [Trial("x", {"i": i}, 0) for i in range(2)]
    store = SweepStore(tmp_path)
    store.open(trials, {})
    store.append(_row(trials[0], 0.1))
    with store.rows_path.open("ab") as f:
        f.write(b"{not json\n")
    store.append(_row(trials[1], 0.2))
    with pytest.raises(InputError, match=r"rows\.jsonl:2: not a JSON row"):
        SweepStore(tmp_path).open(trials, {})
    with pytest.raises(InputError, match="holds another sweep"):
        SweepStore(tmp_path).open([Trial("x", {"i": 7}, 0)], {})
    other = tmp_path / "other"
    SweepStore(other).open(trials[:1], {})
    SweepStore(other).append(_row(trials[1], 0.2))
    with pytest.raises(InputError, match="a row of no trial of this sweep"):
        SweepStore(other).open(trials[:1], {})


def test_split_and_merge_give_back_the_row() -> None:
    row = {"a": 1.25, "wall_s_per_pick": 3.1, "cycle": {"picks": 2, "wait_s": 0.4}, "x": [1]}
    out = split_paths(row, ("wall_s_per_pick", "cycle.wait_s", "cycle.nothing", "missing"))
    assert out.result == {"a": 1.25, "cycle": {"picks": 2}, "x": [1]}
    assert out.timing == {"wall_s_per_pick": 3.1, "cycle": {"wait_s": 0.4}}
    assert merge_paths(out.result, out.timing) == row


def _flaky(config: Mapping[str, Any], seed: int) -> TrialOutput:
    if config["i"] == 2 and not Path(config["ok"]).exists():
        raise RuntimeError("trial 2 breaks")
    return TrialOutput({"square": config["i"] ** 2 + seed}, {"cpu_s": 0.0})


def test_a_failed_trial_stops_the_sweep_and_a_rerun_resumes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(trial_mod.EXPERIMENTS, "flaky", f"{__name__}:_flaky")
    ok = tmp_path / "ok"
    trials = [Trial("flaky", {"i": i, "ok": str(ok)}, 10) for i in range(4)]
    with pytest.raises(RuntimeError, match="trial 2 breaks"):
        run_sweep(trials, tmp_path / "sweep")
    assert len(SweepStore(tmp_path / "sweep").finished()) == 2
    ok.touch()
    run = run_sweep(trials, tmp_path / "sweep")
    assert (run.ran, run.resumed) == (2, 2)
    assert [r["result"]["square"] for r in run.rows] == [10, 11, 14, 19]
    for row in run.rows:
        assert set(row["provenance"]) >= {"git", "packages", "host", "pid"}
        assert row["timing"]["wall_s"] >= 0.0
