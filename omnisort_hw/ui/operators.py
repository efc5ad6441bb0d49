"""Operator sign-ins: one per browser session, kept in this process. The token a person types
is checked by the service (`describe` needs it) and stays here: it never goes back to the
browser, and a page only learns whether its session is signed in."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, TypeVar

from omnisort_hw.pipeline.replies import CommandDescription
from omnisort_hw.request_fields import build
from omnisort_hw.service.commands import Call, CellCommands, call_of
from omnisort_hw.service.protocol import COMMANDS
from omnisort_hw.ui.link import ClientError, CommandError, ServiceLink
from omnisort_hw.ui.schema_form import problems

R = TypeVar("R")
Q = TypeVar("Q")
DESCRIBE = call_of(CellCommands.describe)


class SignInError(Exception):
    """A sign-in that did not take: the reason, for the page."""


class Operators:
    """The tokens of the browser sessions signed in as operators, and the command schemas
    (`describe`) the service gave the last sign-in."""

    def __init__(self, link: ServiceLink, allowed: bool) -> None:
        self.link, self.allowed = link, allowed
        self._tokens: dict[str, str] = {}
        self._lock = threading.Lock()
        self.commands: dict[str, CommandDescription] = {}  # as the service described them

    def token(self, browser: str) -> str | None:
        with self._lock:
            return self._tokens.get(browser)

    def signed_in(self, browser: str) -> bool:
        return self.token(browser) is not None

    def sign_in(self, browser: str, token: str) -> None:
        """Check `token` with the service and keep it for this browser session."""
        if not self.allowed:
            raise SignInError("this screen is view-only ([ui] allow_operator = false)")
        try:
            described = self.link.call(DESCRIBE, token=token.strip() or None)
        except CommandError as exc:
            if exc.code == "unauthorized":
                raise SignInError("wrong token: the service refused it") from None
            raise SignInError(f"the service refused the sign-in: {exc.message}") from None
        except ClientError as exc:
            raise SignInError(f"the service cannot be reached: {exc}") from None
        with self._lock:
            self._tokens[browser] = token.strip()
            self.commands = dict(described.commands)

    def sign_out(self, browser: str) -> None:
        with self._lock:
            self._tokens.pop(browser, None)

    def schema(self, command: Callable[..., Any]) -> dict[str, Any] | None:
        """The `args` schema of `command` (a `CellCommands` method), as the service described
        it; None before a sign-in."""
        with self._lock:
            spec = self.commands.get(command.__name__)
        return dict(spec.args) if spec else None

    def problems(self, command: Callable[..., Any], args: dict[str, Any]) -> list[str]:
        """What `command`'s schema finds wrong with `args`, each naming its field (nothing
        before a sign-in: the service refuses then)."""
        schema = self.schema(command)
        return problems(schema, args) if schema is not None else []

    def checked(
        self, command: Callable[[CellCommands, Q], R], args: dict[str, Any]
    ) -> Call[R] | list[str]:
        """The call of `command` (a `CellCommands` method) with a form's `args`, its request
        record built from them once the schema finds nothing wrong; else what it found."""
        if found := self.problems(command, args):
            return found
        request = COMMANDS[command.__name__].request
        return Call(command, build(request, args) if request is not None else None)
