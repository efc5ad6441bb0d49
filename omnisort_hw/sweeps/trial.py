"""One trial of an experiment: (experiment, configuration, seed), keyed by a content hash.

An experiment's trial function takes (config, seed) and returns a `TrialOutput`: `result`,
which depends on the inputs only (byte-identical wherever it runs), and `timing`, which
depends on the machine (wall and CPU times). Functions are named in `EXPERIMENTS` as
"module:function" and imported where the trial runs, so a worker loads only what it needs.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from omnisort_hw.errors import InputError

# experiment -> its trial function, imported lazily (see module docstring).
EXPERIMENTS: dict[str, str] = {
    "table3": "omnisort_hw.evaluation.table3_trials:table3_trial",
    "sorting": "omnisort_hw.evaluation.sorting:sorting_trial",
    "lighting": "omnisort_hw.evaluation.lighting:lighting_trial",
    "drift": "omnisort_hw.evaluation.drift:drift_trial",
}


def canonical_json(value: object) -> str:
    """The one text of a JSON value: sorted keys, no spaces, exact floats (repr)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True)


@dataclass(frozen=True)
class Trial:
    """What a trial computes: `config` and `seed` are its only inputs (JSON values)."""

    experiment: str
    config: Mapping[str, object]
    seed: int

    @property
    def key(self) -> str:
        """Content hash of (experiment, config, seed): the same trial has the same key on
        every machine and in every run, so a resumed sweep recognises what it finished."""
        text = canonical_json(
            {"experiment": self.experiment, "config": self.config, "seed": self.seed}
        )
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    def to_dict(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "experiment": self.experiment,
            "config": dict(self.config),
            "seed": self.seed,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Trial:
        return cls(str(d["experiment"]), dict(d["config"]), int(d["seed"]))


@dataclass
class TrialOutput:
    """A trial function's answer: `result` (inputs only) and `timing` (this machine's)."""

    result: dict[str, Any]
    timing: dict[str, Any] = field(default_factory=dict)


def trial_function(experiment: str) -> Callable[[Mapping[str, object], int], TrialOutput]:
    """The experiment's trial function (InputError for an unknown experiment)."""
    try:
        target = EXPERIMENTS[experiment]
    except KeyError:
        known = ", ".join(sorted(EXPERIMENTS))
        raise InputError(f"unknown experiment {experiment!r} (known: {known})") from None
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def run_trial(trial: Mapping[str, object]) -> dict[str, Any]:
    """Run one trial (a `Trial.to_dict()`) and return its row: the trial, its result, its
    timing (with the trial's wall and CPU time: the CPU time sizes a cluster whatever the
    machine's load) and the provenance of the process that ran it. The
    executors send this function to their workers."""
    from omnisort_hw.sweeps.provenance import provenance

    t = Trial.from_dict(trial)
    fn = trial_function(t.experiment)
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(t.config, t.seed)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    # A result that cannot round-trip through JSON exactly fails here, not in the file.
    result = json.loads(canonical_json(out.result))
    return {
        **t.to_dict(),
        "result": result,
        "timing": {**out.timing, "wall_s": round(wall, 4), "cpu_s": round(cpu, 4)},
        "provenance": provenance(),
    }


def split_paths(row: Mapping[str, object], paths: tuple[str, ...]) -> TrialOutput:
    """Split a row into result and timing: `paths` ("key", "key.sub", ...) name its
    machine-dependent entries, moved to timing under the same path (absent ones skipped)."""
    result: dict[str, Any] = json.loads(canonical_json(row))
    timing: dict[str, Any] = {}
    for path in paths:
        *heads, last = path.split(".")
        src, dst = result, timing
        for head in heads:
            if not isinstance(src.get(head), dict):
                break
            src, dst = src[head], dst.setdefault(head, {})
        else:
            if last in src:
                dst[last] = src.pop(last)
    return TrialOutput(result, _prune(timing))


def _prune(d: dict[str, Any]) -> dict[str, Any]:
    """`d` without the empty dicts a skipped path left."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            v = _prune(v)
            if not v:
                continue
        out[k] = v
    return out


def merge_paths(result: Mapping[str, object], timing: Mapping[str, object]) -> dict[str, Any]:
    """The row `split_paths` split (the trial's own `wall_s` and `cpu_s`, added by
    `run_trial`, left out)."""
    row: dict[str, Any] = json.loads(canonical_json(result))
    _merge(row, {k: v for k, v in timing.items() if k not in ("wall_s", "cpu_s")})
    return row


def _merge(dst: dict[str, Any], src: Mapping[str, object]) -> None:
    for k, v in src.items():
        if isinstance(v, dict) and isinstance(dst.get(k), dict):
            _merge(dst[k], v)
        else:
            dst[k] = v
