"""Every request a test sends through `Client.call` is checked against the command's JSON
Schema by an independent validator (`jsonschema`): a request the service took must be valid, a
request it refused as `bad_argument` must be invalid. So the schema `describe` gives clients
and the checks the protocol runs are held to one declaration by the whole suite."""

from __future__ import annotations

from functools import cache
from typing import Any

from jsonschema import Draft202012Validator

from omnisort_hw.service.protocol import COMMANDS


@cache
def validator(cmd: str) -> Draft202012Validator:
    schema = COMMANDS[cmd].schema()
    Draft202012Validator.check_schema(schema)
    return Draft202012Validator(schema)


def schema_accepts(cmd: str, args: dict[str, Any] | None) -> bool:
    return validator(cmd).is_valid(args or {})


def check_agreement(cmd: Any, args: Any, reply: dict[str, Any]) -> None:
    """Assert that the schema agrees with the service's reply to (cmd, args)."""
    if not isinstance(cmd, str) or cmd not in COMMANDS or not isinstance(args, dict | None):
        return
    error = reply.get("error") or {}
    if reply.get("ok"):
        errors = [e.message for e in validator(cmd).iter_errors(args or {})]
        assert not errors, f"the service took {cmd} {args}, its schema refuses it: {errors}"
    elif error.get("code") == "bad_argument":
        assert not schema_accepts(cmd, args), (
            f"the service refused {cmd} {args} ({error.get('message')}), its schema takes it"
        )
