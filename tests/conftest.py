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
QUICK_MODULE_S = 5.0
"""A test module whose tests took longer than this (setup, call and teardown summed over its
tests, on the run that recorded `timings.json`) is left out of `--quick`."""


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


def _group(item: pytest.Item) -> str:
    """The unit a worker takes whole: the module's `xdist_group` (modules that share what a
    session fixture starts, such as one commissioned virtual cell), else the module."""
    mark = item.get_closest_marker("xdist_group")
    if mark is not None:
        return str(mark.args[0] if mark.args else mark.kwargs.get("name", "default"))
    return item.nodeid.split("::")[0]


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`--quick` leaves the slow modules out; otherwise the groups (`_group`) run longest first
    (by timings.json, summed over a group's modules; an unrecorded module first), each group's
    tests in their own order. With `--dist loadgroup --no-loadscope-reorder` a worker takes
    each group whole, in this order, so the longest ones do not start last and leave the other
    cores idle at the end, and the modules of a group share their session fixtures. Every
    module without a group of its own is its own group (`xdist_group` added here)."""
    import json

    timings = json.loads(TIMINGS.read_text(encoding="utf-8")) if TIMINGS.is_file() else {}

    def seconds(item: pytest.Item, unrecorded: float) -> float:
        return float(timings.get(item.nodeid.split("::")[0], unrecorded))

    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(_group(item)))
    if not config.getoption("--quick"):
        modules: dict[str, set[str]] = {}
        for item in items:
            modules.setdefault(_group(item), set()).add(item.nodeid.split("::")[0])
        group_s = {
            g: sum(float(timings.get(m, float("inf"))) for m in ms) for g, ms in modules.items()
        }
        items.sort(key=lambda i: -group_s[_group(i)])  # stable: groups stay together
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
