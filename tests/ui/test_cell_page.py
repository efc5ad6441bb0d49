"""The cell page with NiceGUI's simulated user against a real `omnisort serve` on the simulated
cell (a child process on loopback, the arm paced to the wall clock): the page shows the service
as it is, keeps operator actions behind a sign-in per browser session, and meets bad input,
a service that is down or restarts mid-sort, and two browsers at once with a clear message and
nothing sent."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from omnisort_hw.config.ui import UiConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.launch import start_service
from omnisort_hw.ui.app import root
from omnisort_hw.ui.context import UiContext
from tests.ui.browser_page import UI_S
from tests.ui.ui_procs import TOKEN, free_port, sim_cell_file

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


async def until(what: str, predicate: Callable[[], Any], timeout_s: float) -> Any:
    """Wait (letting the page's timers run) until `predicate` is true; fail naming `what`."""
    deadline = time.monotonic() + timeout_s
    while not (value := predicate()):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        await asyncio.sleep(0.1)
    return value


def label(user: Any, name: str) -> str:
    """The text of the page's element named `name`."""
    (element,) = user.find(marker=name).elements
    return str(element.text)


def set_value(user: Any, name: str, value: Any) -> None:
    with user.client:
        for element in user.find(marker=name).elements:
            element.value = value


def status(port: int) -> dict[str, Any]:
    with Client("127.0.0.1", port, timeout_s=10) as c:
        return dict(c.status())


def simulate(ctx: UiContext, scenario: Callable[..., Any]) -> None:
    """Run `scenario(user, new_user)` against the page of `ctx` in NiceGUI's simulation."""
    import httpx
    from nicegui import core
    from nicegui.testing.user import User
    from nicegui.testing.user_simulation import user_simulation

    async def main() -> None:
        async with user_simulation(root(ctx)) as user:

            def new_user() -> User:
                transport = httpx.ASGITransport(core.app)
                return User(httpx.AsyncClient(transport=transport, base_url="http://test"))

            await scenario(user, new_user)

    try:
        asyncio.run(main())
    finally:
        ctx.close()


def context(port: int) -> UiContext:
    return UiContext.for_service(UiConfig(status_period_s=0.2), "127.0.0.1", port)


def test_page_shows_the_service_guards_operator_actions_and_checks_the_schema(
    tmp_path: Path,
) -> None:
    config = sim_cell_file(tmp_path, realtime=True)
    with start_service(config, tmp_path) as svc:

        async def scenario(user: Any, new_user: Callable[[], Any]) -> None:
            await user.open("/")
            await until("the state", lambda: label(user, "state") == "idle", UI_S)
            await user.should_see("Read-only: sign in for operator actions")
            await user.should_not_see(marker="start-sort")
            await user.should_not_see(marker="laser-off")
            # The live picture needs no sign-in (as `status`); the map and locate buttons do.
            await until(
                "a live picture", lambda: label(user, "view-note").startswith("picture"), UI_S
            )
            await user.should_not_see(marker="map")

            set_value(user, "token", "wrong")
            user.find(marker="sign-in").click()
            await until("wrong token", lambda: "wrong token" in label(user, "message"), UI_S)
            await user.should_not_see(marker="start-sort")

            set_value(user, "token", TOKEN)
            user.find(marker="sign-in").click()
            await until(
                "the sign-in", lambda: label(user, "signed") == "Signed in as operator", UI_S
            )
            await user.should_see(marker="start-sort")

            # Bad values: each refused by the schema, nothing sent.
            before = status(svc.port)["service"]
            for value, expected in ((0, "minimum of 1"), (2.5, "not of type 'integer'")):
                set_value(user, "sort-max_objects", value)
                user.find(marker="start-sort").click()
                await until(expected, lambda e=expected: e in label(user, "sort-problems"), UI_S)
                await user.should_not_see(marker="confirm")
            after = status(svc.port)
            assert after["last_run"] is None and after["service"]["errors"] == before["errors"]

            # A second browser: its own session, read-only until it signs in itself.
            other = new_user()
            await other.open("/")
            await until("the state", lambda: label(other, "state") == "idle", UI_S)
            await other.should_not_see(marker="start-sort")

            # The laser: switched by the operator, seen by both pages through the status.
            user.find(marker="laser-off").click()
            await until("laser off", lambda: "laser off" in label(user, "message"), UI_S)
            await until(
                "the laser off on the other page",
                lambda: any("laser" in r["v"] and r["v"].endswith("off") for r in _rows(other)),
                UI_S,
            )

            # A sort started here, then a second one asked from the other browser: refused.
            set_value(user, "sort-max_objects", 1)
            user.find(marker="start-sort").click()
            await user.should_see(marker="confirm")
            user.find(marker="cancel").click()
            await until("the cancel", lambda: "cancelled" in label(user, "message"), UI_S)
            assert status(svc.port)["last_run"] is None
            user.find(marker="start-sort").click()
            await user.should_see(marker="confirm")
            user.find(marker="confirm").click()
            await until("sorting", lambda: label(other, "state") == "sorting", UI_S)
            set_value(other, "token", TOKEN)
            other.find(marker="sign-in").click()
            await until("the sign-in", lambda: "Signed in" in label(other, "signed"), UI_S)
            # The other browser is not offered a sort while one runs: Start sort is disabled.
            await until("Start disabled", lambda: not _enabled(other, "start-sort"), UI_S)
            other.find(marker="start-sort").click()
            await other.should_not_see(marker="confirm")
            await until("the sort's end", lambda: "sort done" in label(user, "job-end"), 120)
            await until("the log", lambda: len(_rows(other, "pick-log")) == 1, UI_S)
            st = status(svc.port)
            assert [ev["status"] for ev in st["last_run"]["progress"] if "cube" in ev] == ["sorted"]
            assert st["last_run"]["request_id"] == 1, "the refused sort reached the service"

        simulate(context(svc.port), scenario)


def _enabled(user: Any, name: str) -> bool:
    (element,) = user.find(marker=name).elements
    return bool(element.enabled)


def _rows(user: Any, name: str = "status-rows") -> list[dict[str, Any]]:
    (table,) = user.find(marker=name).elements
    return list(table.rows)


def test_page_outlives_a_service_restart_mid_sort_and_a_service_that_is_down(
    tmp_path: Path,
) -> None:
    config = sim_cell_file(tmp_path, realtime=True)
    port = free_port()
    svc = start_service(config, tmp_path / "first", port=port)

    async def scenario(user: Any, new_user: Callable[[], Any]) -> None:
        nonlocal svc
        await user.open("/")
        await until("the state", lambda: label(user, "state") == "idle", UI_S)
        set_value(user, "token", TOKEN)
        user.find(marker="sign-in").click()
        await until("the sign-in", lambda: "Signed in" in label(user, "signed"), UI_S)
        user.find(marker="start-sort").click()
        await user.should_see(marker="confirm")
        user.find(marker="confirm").click()
        await until("the first pick", lambda: _rows(user, "pick-log"), 120)

        # The service restarts (systemd's SIGTERM, then a new process) mid-sort.
        await asyncio.to_thread(svc.stop)
        await until("unreachable", lambda: label(user, "state") == "unreachable", UI_S)
        await user.should_see(marker="unreachable")
        ended = await until("the job's end", lambda: label(user, "job-end"), UI_S)
        assert ended.startswith("sort: ") and "Traceback" not in ended, ended
        # While it is down: nothing can be sent, and the page says so.
        user.find(marker="stop").click()
        await until("not sent", lambda: "not sent" in label(user, "message"), 5)
        await until("Start disabled", lambda: not _enabled(user, "start-sort"), UI_S)
        user.find(marker="start-sort").click()
        await user.should_not_see(marker="confirm")
        assert not _rows(user), "the status of a service that is down is still shown"

        svc = await asyncio.to_thread(start_service, config, tmp_path / "second", 120.0, None, port)
        await until("the service back", lambda: label(user, "state") != "unreachable", UI_S)
        await user.should_not_see(marker="unreachable")
        # What was said while it was down is gone with it; Start is offered again.
        await until("the message gone", lambda: "not sent" not in label(user, "message"), UI_S)
        await until("Start enabled", lambda: _enabled(user, "start-sort"), UI_S)
        print(f"\nthe page after the restart mid-sort: {ended}")
        st = status(port)
        assert st["last_run"]["state"] in ("stopped", "interrupted"), st["last_run"]

    try:
        simulate(context(port), scenario)
    finally:
        svc.stop()


def test_view_only_screen_offers_no_sign_in_but_stop(tmp_path: Path) -> None:
    """`[ui] allow_operator = false`: the cell and the live picture, Stop and E-stop, and no
    way to sign in; Stop still reaches the service (open to everyone, as in the protocol)."""
    config = sim_cell_file(tmp_path, realtime=False)
    with start_service(config, tmp_path) as svc:
        ctx = UiContext.for_service(
            UiConfig(status_period_s=0.2, allow_operator=False), "127.0.0.1", svc.port
        )

        async def scenario(user: Any, new_user: Callable[[], Any]) -> None:
            await user.open("/")
            await until("the state", lambda: label(user, "state") == "idle", UI_S)
            await user.should_see(marker="view-only")
            for hidden in ("token", "sign-in", "start-sort", "laser-on", "map"):
                await user.should_not_see(marker=hidden)
            await until("a picture", lambda: label(user, "view-note").startswith("picture"), UI_S)
            user.find(marker="stop").click()
            await until("stopped", lambda: label(user, "state") == "stopped", UI_S)
            assert status(svc.port)["state"] == "stopped"

        simulate(ctx, scenario)
