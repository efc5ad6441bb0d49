"""`omnisort ctl [--host H --port P --token T] COMMAND [key=value ...]`: talk to the service.

Values are read as JSON when they parse (`on=true`, `joints_deg=[0,-90,90,0,90,0]`,
`max_objects=3`) and as plain strings otherwise (`folder=/data/calib`; a relative path is made
absolute here); a list also as `colors=red,blue`. `omnisort ctl describe` lists each command's
arguments. `describe` lists every command and its arguments (`--json`: their JSON
Schema). `status` and a job's reply print a one-screen summary (a job's: its verdict,
figures and files; `--json`: the whole reply); other replies are printed as JSON; a job shows
its progress on the terminal. The exit code is 0 for an ok reply, 1 for an error reply, 3 when
the service cannot be reached or does not answer in time, 4 when `check` found the camera
turned (as `omnisort check`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from omnisort_hw.cli.arg_types import Subcommands
from omnisort_hw.cli.output import EXIT_DRIFT

EXIT_ERROR_REPLY = 1
EXIT_UNREACHABLE = 3


def register(sub: Subcommands) -> None:
    p = sub.add_parser(
        "ctl",
        help="send one command to the running service and print the reply",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", default=None, help="read host, port and token from this file")
    p.add_argument("--host", default=None, help="service address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="service port")
    p.add_argument(
        "--token", default=None, help="service token (default: $OMNISORT_TOKEN or --config)"
    )
    p.add_argument("--timeout", type=float, default=None, help="reply timeout, s")
    p.add_argument("--connect-timeout", type=float, default=5.0, help="connect timeout, s")
    p.add_argument("--compact", action="store_true", help="print the reply on one line")
    p.add_argument(
        "--json",
        action="store_true",
        help="print the whole reply as JSON (status otherwise prints a one-screen summary)",
    )
    p.add_argument("command", help="status, capture, laser, calibrate, move, sort, stop, ...")
    p.add_argument("args", nargs="*", metavar="key=value", help="command arguments")
    p.set_defaults(func=run)


def parse_kv(items: list[str]) -> dict[str, Any]:
    """`key=value` pairs to an args dict; values are JSON when they parse, else strings."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            from omnisort_hw.errors import InputError

            raise InputError(f"argument {item!r} is not key=value")
        try:
            out[key] = json.loads(raw)
        except ValueError:
            out[key] = raw
    return out


def typed_args(command: str, args: dict[str, Any], host: str) -> dict[str, Any]:
    """The command's arguments read by their declared kinds: a list as `red,blue` as well as
    JSON, and a path made absolute against this shell's folder when the service runs on this
    machine (loopback): a service under systemd runs in `/`, so a relative `folder=views` would
    name a different folder there. Anything else goes as typed, for the service to check."""
    from omnisort_hw.config.service import is_loopback
    from omnisort_hw.request_fields import split_items
    from omnisort_hw.service.protocol import COMMANDS

    spec = COMMANDS.get(command)
    if spec is None:
        return args
    out = dict(args)
    for arg in spec.args:
        value = out.get(arg.name)
        if not isinstance(value, str) or not value:
            continue
        if arg.kind == "path" and is_loopback(host):
            out[arg.name] = os.path.abspath(os.path.expanduser(value))
        elif arg.kind == "str_list":
            out[arg.name] = list(split_items(value))
    return out


def default_timeout(command: str) -> float:
    """Long commands may take minutes; quick ones answer in seconds."""
    from omnisort_hw.service.protocol import COMMANDS

    spec = COMMANDS.get(command)
    return 3600.0 if spec is not None and spec.kind == "job" else 30.0


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.config.service import DEFAULT_PORT, client_host
    from omnisort_hw.service.client import Client, ClientError

    host, port, token = "127.0.0.1", DEFAULT_PORT, None
    if args.config:
        from omnisort_hw.config.cell import load_cell_config

        svc = load_cell_config(args.config).service
        host = client_host(svc.host)
        port, token = svc.port, svc.token
    host = args.host or host
    port = args.port if args.port is not None else port
    token = args.token or os.environ.get("OMNISORT_TOKEN") or token
    cmd_args = typed_args(args.command, parse_kv(args.args), host)
    timeout = args.timeout if args.timeout is not None else default_timeout(args.command)
    try:
        with (
            Client(
                host, port, token, timeout_s=timeout, connect_timeout_s=args.connect_timeout
            ) as c,
            JobProgress(args.command) as progress,
        ):
            reply = c.call(args.command, cmd_args or None, on_event=progress.on_event)
            if progress.on_event is not None and _refused_progress(reply):
                reply = c.call(args.command, cmd_args or None)  # a service before progress
    except ClientError as exc:
        print(f"omnisort ctl: {exc}", file=sys.stderr)
        return EXIT_UNREACHABLE
    if args.command == "status" and reply.get("ok") and not (args.json or args.compact):
        from omnisort_hw.service.status_reading import summarise

        print(summarise(reply["result"]))
    elif args.command == "describe" and reply.get("ok") and not (args.json or args.compact):
        from omnisort_hw.cli.reply_summary import summarise_describe

        print(summarise_describe(reply["result"]))
    elif reply.get("ok") and progress.is_job and not (args.json or args.compact):
        from omnisort_hw.cli.reply_summary import summarise_reply

        print(summarise_reply(args.command, reply["result"]))
    else:
        print(json.dumps(reply, indent=None if args.compact else 2))
    if not reply.get("ok"):
        return EXIT_ERROR_REPLY
    return EXIT_DRIFT if args.command == "check" and reply["result"].get("drift") else 0


def _refused_progress(reply: dict[str, Any]) -> bool:
    error = reply.get("error") or {}
    return error.get("code") == "bad_request" and "'progress'" in str(error.get("message"))


class JobProgress:
    """A job's progress events as a bar on stderr (off when stderr is not a terminal, so
    scripts and journald see only the reply). `on_event` is None for commands that are not
    jobs: only jobs send events."""

    def __init__(self, command: str) -> None:
        from omnisort_hw.service.protocol import COMMANDS

        spec = COMMANDS.get(command)
        self.command = command
        self.is_job = spec is not None and spec.kind == "job"
        self.on_event = self._event if self.is_job else None
        self._bar: Any = None

    def __enter__(self) -> JobProgress:
        if self.on_event is not None:
            from tqdm import tqdm

            self._bar = tqdm(
                desc=self.command,
                file=sys.stderr,
                disable=None,
                bar_format="{desc}: running {elapsed}{postfix}",
            )
            if self._bar.disable:  # not a terminal: no bar, so no events asked for
                self.on_event = None
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()

    def _event(self, event: dict[str, Any]) -> None:
        bar = self._bar
        if bar is None:
            return
        if "to_pick" in event:
            bar.bar_format = None  # a count is known now: the usual bar
            bar.reset(total=int(event["to_pick"]))
            bar.unit = "cube"
            bar.set_postfix_str(f"{event.get('located', '?')} located")
        elif "cube" in event:
            bar.update(1)
            bar.set_postfix_str(
                f"cube {event['cube']} {event.get('status', '')} ({event.get('color', '?')})"
            )
        elif isinstance(event.get("expected_s"), int | float):
            bar.set_postfix_str(f", about {event['expected_s']:.0f} s (its last run here)")
        elif "running_s" not in event and "stage" not in event:
            bar.set_postfix_str(", ".join(f"{k} {v}" for k, v in event.items()))
        bar.refresh()
