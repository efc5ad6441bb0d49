"""Shared fixtures: the third-party reference images and a scratch directory."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

PROJECT_ROOT = Path(__file__).resolve().parent.parent
REFERENCE_DIR = PROJECT_ROOT.parent / "shared" / "reference" / "unity"


@pytest.fixture(autouse=True)
def _requests_match_the_schema(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each request sent through `Client.call` in any test is checked against its command's
    JSON Schema (tests/schema_agreement.py)."""
    from omnisort_hw.service.client import Client
    from tests.schema_agreement import check_agreement

    call = Client.call

    def checked(self: Client, cmd: str, args: Any = None, *a: Any, **kw: Any) -> Any:
        reply = call(self, cmd, args, *a, **kw)
        check_agreement(cmd, args, reply)
        return reply

    monkeypatch.setattr(Client, "call", checked)


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    """`../shared/reference/unity`, or a skip with the reason when this checkout has none."""
    if not REFERENCE_DIR.is_dir():
        pytest.skip(f"third-party reference images not found at {REFERENCE_DIR}")
    return REFERENCE_DIR


# -- the edit loop's selection (`make check`) -------------------------------------------------

TIMINGS = Path(__file__).with_name("timings.json")
QUICK_MODULE_S = 4.0
"""A test module whose tests took longer than this (setup, call and teardown summed over its
tests, on the run that recorded `timings.json`) is left out of `--quick`. 4 s keeps `make
check` under 2 minutes on 2 cores: on the fresh-clone recording of ad51b8c, the 93 modules
under it sum to 91 s, the 107 under 5 s to 154 s (136 s of `make check`)."""


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--quick",
        action="store_true",
        help=f"only the test modules that took under {QUICK_MODULE_S:g} s in tests/timings.json "
        "(a module not recorded there runs)",
    )
    parser.addoption(
        "--record-timings",
        metavar="FILE",
        default=None,
        help="write each test module's time (s, setup + call + teardown) to FILE as JSON",
    )


SHARED_GROUPS = ("tests/ui/commissioned/",)
"""Test packages whose modules share what a session fixture starts (one commissioned virtual
cell): a worker takes each whole, its modules in their order, so it is built once."""


def group_of(nodeid: str) -> str:
    """The unit a worker takes whole: a shared package (`SHARED_GROUPS`), else the module."""
    module = nodeid.split("::")[0]
    return next((g for g in SHARED_GROUPS if module.startswith(g)), module)


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """The workers take whole groups (`group_of`) in the collection's order (longest first,
    below): xdist's load-scope scheduling, split by group instead of by module. (Its own
    `xdist_group` marks do not reach the scheduler under pytest 9.2, whose items no longer
    take the `@group` suffix xdist writes into their node ids.)"""
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

    return GroupScheduling(config, log)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`--quick` leaves the slow modules out; otherwise the groups (`group_of`) run longest
    first (by timings.json, summed over a group's modules; an unrecorded module first), each
    group's tests in their own order. With `--no-loadscope-reorder` the workers take the
    groups in this order, so the longest ones do not start last and leave the other cores
    idle at the end."""
    import json

    timings = json.loads(TIMINGS.read_text(encoding="utf-8")) if TIMINGS.is_file() else {}

    def seconds(item: pytest.Item, unrecorded: float) -> float:
        return float(timings.get(item.nodeid.split("::")[0], unrecorded))

    if not config.getoption("--quick"):
        modules: dict[str, set[str]] = {}
        for item in items:
            modules.setdefault(group_of(item.nodeid), set()).add(item.nodeid.split("::")[0])
        group_s = {
            g: sum(float(timings.get(m, float("inf"))) for m in ms) for g, ms in modules.items()
        }
        items.sort(key=lambda i: -group_s[group_of(i.nodeid)])  # stable: groups stay together
        return
    slow = [i for i in items if seconds(i, 0.0) > QUICK_MODULE_S]
    if slow:
        config.hook.pytest_deselected(items=slow)
        left_out = {id(i) for i in slow}
        items[:] = [i for i in items if id(i) not in left_out]


_module_seconds: dict[str, float] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    module = report.nodeid.split("::")[0]
    _module_seconds[module] = _module_seconds.get(module, 0.0) + report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = session.config.getoption("--record-timings")
    if path is None or hasattr(session.config, "workerinput"):  # the controller writes it
        return
    import json

    rounded = {k: round(v, 2) for k, v in sorted(_module_seconds.items())}
    Path(path).write_text(json.dumps(rounded, indent=1) + "\n", encoding="utf-8")
