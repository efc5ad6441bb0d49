"""`omnisort ctl`, `omnisort review` and `omnisort serve` from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from omnisort_hw.cli import main
from omnisort_hw.cli.ctl_cmd import parse_kv
from omnisort_hw.runlog import RunLog
from tests.service.conftest import TOKEN, Harness

pytestmark = pytest.mark.timeout(60)


def test_parse_kv() -> None:
    assert parse_kv(["on=true", "joints_deg=[0,-90,90,0,90,0]", "folder=/data/x", "n=3"]) == {
        "on": True,
        "joints_deg": [0, -90, 90, 0, 90, 0],
        "folder": "/data/x",
        "n": 3,
    }


def test_ctl_prints_the_reply_and_sets_the_exit_code(make_service, capsys) -> None:
    h: Harness = make_service(token=TOKEN)
    port = str(h.running.port)
    assert main(["ctl", "--port", port, "--compact", "status"]) == 0
    reply = json.loads(capsys.readouterr().out)
    assert reply["ok"] and reply["result"]["state"] == "idle"
    assert main(["ctl", "--port", port, "laser", "on=true"]) == 1
    assert json.loads(capsys.readouterr().out)["error"]["code"] == "unauthorized"
    assert main(["ctl", "--port", port, "--token", TOKEN, "laser", "on=true"]) == 0
    assert json.loads(capsys.readouterr().out)["result"] == {"on": True}
    assert main(["ctl", "--port", port, "--token", TOKEN, "move", "joints_deg=[1,2]"]) == 1
    assert json.loads(capsys.readouterr().out)["error"]["code"] == "bad_argument"


def test_ctl_reads_host_port_token_from_the_config(make_service, tmp_path, capsys) -> None:
    h: Harness = make_service(token=TOKEN)
    cfg = tmp_path / "cell.toml"
    cfg.write_text(f'[service]\nport = {h.running.port}\ntoken = "{TOKEN}"\n')
    assert main(["ctl", "--config", str(cfg), "capture"]) == 0
    assert Path(json.loads(capsys.readouterr().out)["result"]["path"]).is_file()


def test_ctl_sends_paths_made_absolute_where_it_was_typed(
    make_service, tmp_path, capsys, monkeypatch
) -> None:
    """`ctl calibrate folder=views` means ./views of the shell, not of the service (which runs
    in `/` under systemd); a relative path sent by another client is refused by name."""
    h: Harness = make_service(token=TOKEN)
    port = str(h.running.port)
    monkeypatch.chdir(tmp_path)
    argv = ["ctl", "--port", port, "--token", TOKEN, "--compact", "calibrate"]
    assert main([*argv, "what=intrinsics", "folder=views", "square_mm=20"]) == 1
    err = json.loads(capsys.readouterr().out)["error"]
    assert err["code"] == "bad_input" and str(tmp_path / "views") in err["message"], err
    with h.client(token=TOKEN) as c:
        r = c.call("calibrate", {"what": "intrinsics", "folder": "views", "square_mm": 20})
    assert r["error"]["code"] == "bad_argument" and "absolute path" in r["error"]["message"]
    assert "folder" in r["error"]["message"] and str(Path.cwd()) in r["error"]["message"]


def test_ctl_reads_a_list_argument_as_comma_separated(monkeypatch) -> None:
    from omnisort_hw.cli.ctl_cmd import parse_kv, typed_args

    args = typed_args("sort", parse_kv(["colors=red, blue", "max_objects=2"]), "127.0.0.1")
    assert args == {"colors": ["red", "blue"], "max_objects": 2}
    assert typed_args("locate", parse_kv(['colors=["red"]']), "127.0.0.1") == {"colors": ["red"]}


def test_ctl_unreachable(capsys) -> None:
    assert main(["ctl", "--port", "1", "--connect-timeout", "1", "status"]) == 3
    assert "cannot connect" in capsys.readouterr().err


def test_review_lists_entities_and_spawns_the_viewer(tmp_path, capsys, monkeypatch) -> None:
    rrd = tmp_path / "run.rrd"
    with RunLog(rrd) as rl:
        rl.event("service/state", "idle -> sorting")
        rl.scalar("calibration/rms_px", 0.2)
    assert main(["review", str(rrd), "--list"]) == 0
    out = capsys.readouterr().out.split()
    assert "/service/state" in out and "/calibration/rms_px" in out
    monkeypatch.setenv("OMNISORT_RERUN", "echo viewer")
    monkeypatch.setenv("DISPLAY", ":0")  # the viewer needs one; the headless case has its test
    assert main(["review", str(rrd)]) == 0
    assert main(["review", str(tmp_path / "missing.rrd")]) == 2
    (tmp_path / "bad.rrd").write_bytes(b"not rerun")
    assert main(["review", str(tmp_path / "bad.rrd"), "--list"]) == 2


def test_serve_reports_a_bad_configuration(tmp_path, capsys) -> None:
    """Exit 78 (EX_CONFIG) for every configuration error: systemd does not restart on it."""
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[service]\nhost = "0.0.0.0"\n')
    assert main(["serve", "--config", str(cfg)]) == 78
    assert "not loopback" in capsys.readouterr().err
    assert main(["serve", "--config", str(tmp_path / "nope.toml")]) == 78
    assert "not found" in capsys.readouterr().err


def test_serve_names_a_device_that_cannot_be_opened(tmp_path, capsys) -> None:
    cfg = tmp_path / "cell.toml"
    cfg.write_text(
        '[camera]\nbackend = "v4l2"\ndevice = "/dev/video-omnisort-missing"\n'
        f'[storage]\nstate_dir = "{tmp_path / "state"}"\n'
        f'[logging]\nlog_dir = "{tmp_path / "logs"}"\n'
    )
    assert main(["serve", "--config", str(cfg), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "/dev/video-omnisort-missing" in err


def test_ctl_describe_lists_each_command_with_its_arguments(make_service, capsys) -> None:
    h: Harness = make_service(token=TOKEN)
    port = str(h.running.port)
    assert main(["ctl", "--port", port, "--token", TOKEN, "describe"]) == 0
    text = capsys.readouterr().out
    assert "calibrate (job): Calibrate: intrinsics from a folder" in text
    assert "    square_mm  number 1.0..1000.0 mm optional: board square size" in text
    assert '    encoding  path|base64 default "path": a file path, or base64' in text
    assert main(["ctl", "--port", port, "--token", TOKEN, "--json", "describe"]) == 0
    schema = json.loads(capsys.readouterr().out)["result"]["commands"]["move"]["args"]
    assert schema["properties"]["joints_deg"]["x-unit"] == "deg"
