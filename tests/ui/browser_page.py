"""The cell page in a real browser for the tests and the benchmark: its elements found by
their data-test names, waits with a deadline, and a page opened (and signed in)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from omnisort_hw.service.client import Client
from omnisort_hw.service.launch import ServiceProcess, start_service
from tests.ui.ui_procs import TOKEN, chromium, quit_chromium, start_ui, stop_process

PROJECT_ROOT = Path(__file__).resolve().parents[2]
IMAGES = Path(os.environ.get("OMNISORT_SCREENSHOTS", PROJECT_ROOT / "build" / "screenshots"))
"""Where the screenshots go: build/screenshots, so a test run leaves the tracked tree as it
was; `make screenshots` points this at docs/images to renew the documentation's pictures."""


UI_S = 60.0
"""How long a page may take to show a state it is bound to reach (a dialog, a step's content, a
note): a guard against a hang, not a bound on latency, which a loaded 2-core runner stretches
to many seconds (Chromium, the interface's process and the service share the cores)."""


def wait_for(
    what: str, predicate: Callable[[], Any], timeout_s: float, every_s: float = 0.1
) -> Any:
    """Poll `predicate` until it returns something true; fail naming `what` after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(every_s)


class Page:
    """The cell page in the browser, found by the elements' data-test names."""

    def __init__(self, driver: Any) -> None:
        self.d = driver

    def el(self, name: str, inner: str = "") -> Any:
        from selenium.webdriver.common.by import By

        return self.d.find_element(By.CSS_SELECTOR, f"[data-test={name}] {inner}".strip())

    def text(self, name: str) -> str:
        """The element's text; empty while it is not on the page (a step still opening)."""
        from selenium.common.exceptions import (
            NoSuchElementException,
            StaleElementReferenceException,
        )

        try:
            return str(self.el(name).text)
        except (NoSuchElementException, StaleElementReferenceException):
            return ""

    def click(self, name: str, timeout_s: float = UI_S) -> None:
        """Click the element once it is shown (a step's content appears after its
        transition), scrolled to the window's middle first."""
        try:
            wait_for(f"{name} to be shown", lambda: self.visible(name), timeout_s, 0.1)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; the page: {self.state_for_a_failure(name)}") from None
        el = self.el(name)
        # In the middle of the window: not under the fixed header, wherever the page scrolled.
        self.d.execute_script("arguments[0].scrollIntoView({block: 'center'})", el)
        # A tab's panel slides in: the pointer clicks where the element is, so it must have
        # come to rest (the same box on two reads in a row), or the click lands beside it.
        boxes: list[object] = []

        def at_rest() -> bool:
            boxes.append(
                self.d.execute_script(
                    "const r = arguments[0].getBoundingClientRect();"
                    "return [r.x, r.y, r.width, r.height];",
                    el,
                )
            )
            return len(boxes) > 1 and boxes[-1] == boxes[-2]

        wait_for(f"{name} to come to rest", at_rest, timeout_s, 0.05)
        el.click()

    def type(self, name: str, value: str) -> None:
        from selenium.webdriver.common.keys import Keys

        wait_for(f"{name} to be shown", lambda: self.visible(name), UI_S, 0.1)
        box = self.el(name)  # Quasar puts the attribute on the <input> itself, or around it
        if box.tag_name != "input":
            box = self.el(name, "input")
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys(Keys.DELETE)
        if value:
            box.send_keys(value)

    def visible(self, name: str) -> bool:
        """Shown now; False when absent, or gone between finding and asking (a tab's panel
        taken out of the page)."""
        from selenium.common.exceptions import (
            NoSuchElementException,
            StaleElementReferenceException,
        )

        try:
            return bool(self.el(name).is_displayed())
        except (NoSuchElementException, StaleElementReferenceException):
            return False

    def pick_rows(self) -> list[list[str]]:
        from selenium.webdriver.common.by import By

        rows = self.el("pick-log").find_elements(By.CSS_SELECTOR, "tbody tr")
        cells = [[td.text for td in r.find_elements(By.CSS_SELECTOR, "td")] for r in rows]
        return [c for c in cells if len(c) == 8]  # #, sort, cube, colour, bin, outcome, ...

    def count(self, name: str, inner: str) -> int:
        from selenium.webdriver.common.by import By

        return len(self.d.find_elements(By.CSS_SELECTOR, f"[data-test={name}] {inner}"))

    def confirm(self) -> None:
        try:
            wait_for("the confirmation", lambda: self.visible("confirm"), UI_S)
        except AssertionError as exc:
            raise AssertionError(
                f"{exc}; the page: {self.state_for_a_failure('confirm')}"
            ) from None
        self.click("confirm")

    def state_for_a_failure(self, name: str) -> str:
        """What the page shows now, for a failure's message: its notes and tabs, and a
        screenshot (`failed_NAME.png` beside the others)."""
        notes = {n: self.text(n) for n in ("state", "message", "sim-note", "drift")}
        tabs = [t for t in ("tab-cell", "tab-commission", "tab-simulator") if self.visible(t)]
        try:
            self.shot(f"failed_{name}")
        except Exception as exc:  # the page may be gone: the message says so
            notes["screenshot"] = repr(exc)
        return f"notes {notes}, tabs shown {tabs}, url {self.d.current_url}"

    def shot(self, name: str, at: str | None = None) -> None:
        """The page from its top, or from the element named `at`."""
        IMAGES.mkdir(parents=True, exist_ok=True)
        if at is None:
            self.d.execute_script("window.scrollTo(0, 0)")
        else:
            self.d.execute_script("arguments[0].scrollIntoView()", self.el(at))
        self.d.save_screenshot(str(IMAGES / f"{name}.png"))


def open_cell_page(
    url: str, sign_in: bool = True, width: int = 1400, height: int = 1800
) -> tuple[Any, Page]:
    """Chromium on the cell page, once it shows the state (and, `sign_in`, signed in with the
    test service's token and showing the sort form)."""
    driver = chromium(width, height)
    try:
        driver.get(url)
        page = Page(driver)
        wait_for("the page", lambda: page.text("state") not in ("", "…"), UI_S)
        if sign_in:
            page.type("token", TOKEN)
            page.click("sign-in")
            wait_for("the sign-in", lambda: page.visible("start-sort"), UI_S)
    except BaseException:
        quit_chromium(driver)
        raise
    return driver, page


@contextmanager
def served_page(
    config: Path, workdir: Path, sign_in: bool = True
) -> Iterator[tuple[ServiceProcess, Page]]:
    """`omnisort serve` on `config`, `omnisort ui` beside it, and Chromium on its page (idle;
    `sign_in`: signed in); each stopped at the end, whatever happened."""
    with start_service(config, workdir) as svc:
        ui_proc, url = start_ui(config, svc.port, workdir)
        try:
            driver, page = open_cell_page(url, sign_in=sign_in)
            try:
                wait_for("the idle cell", lambda: page.text("state") == "idle", UI_S)
                yield svc, page
            finally:
                quit_chromium(driver)
        finally:
            stop_process(ui_proc)


def service_status(port: int) -> dict[str, Any]:
    """The service's `status` now, on a connection of its own."""
    with Client("127.0.0.1", port, timeout_s=10) as c:
        return dict(c.status())
