"""deploy/cell.example.toml says it lists every key: each key the loader reads is written in it
(set, or commented out where it is an alternative), under its section, with a comment; and
every key written in it is one the loader reads. The simulated devices' keys (the drift
rehearsal's `bump_deg`, ...) included."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from omnisort_hw.config.cell import SECTIONS, section_keys
from omnisort_hw.config.devices import SIM_SETTINGS, check_sim_settings

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "cell.example.toml"
KEY = re.compile(r"^(?:# ?)?(\w+)\s*=")
HEADER = re.compile(r"^(?:# ?)?\[+([\w.]+)\]+")


def _documented() -> dict[str, set[str]]:
    """Section -> the keys written under it, set or commented out (`# key = value`); a
    commented `# [section]` header opens a commented section; a simulated device's keys
    are those after its `# backend = "sim"` line."""
    out: dict[str, set[str]] = {}
    section = ""
    for line in EXAMPLE.read_text().splitlines():
        header = HEADER.match(line)
        if header:
            section = header.group(1)
            parent, _, sub = section.partition(".")
            if sub:  # [[sorting.bins]]: the key `bins` of [sorting]
                out.setdefault(parent, set()).add(sub)
            continue
        key = KEY.match(line)
        if key and section:
            if line.startswith("#") and key.group(1) == "backend" and '"sim"' in line:
                section = f"{section.split('.')[0]}.sim"
            out.setdefault(section, set()).add(key.group(1))
    return out


DOCUMENTED = _documented()


@pytest.mark.parametrize("section", sorted(section_keys()))
def test_every_key_of_the_loader_is_in_the_example_and_no_other(section: str) -> None:
    known = section_keys()[section]
    written = DOCUMENTED.get(section, set())
    assert known - written == set(), f"[{section}] keys not in the example"
    assert written - known == set(), f"[{section}] keys the loader does not read"


@pytest.mark.parametrize("kind", sorted(SIM_SETTINGS))
def test_the_simulated_devices_keys_are_in_the_example_and_parse(kind: str) -> None:
    written = DOCUMENTED.get(f"{kind}.sim", set()) - {"backend"}
    assert set(SIM_SETTINGS[kind]) - written == set(), f"[{kind}] sim keys not in the example"
    assert written - set(SIM_SETTINGS[kind]) == set()
    text = EXAMPLE.read_text()
    start = text.index('# backend = "sim"', text.index(f"\n[{kind}]\n"))
    block = []
    for line in text[start:].splitlines():
        if not line.startswith("#"):
            break
        body = line[2:] if line.startswith("# ") else line[1:]
        if KEY.match(body) and not body.startswith("backend"):
            block.append(body)
    check_sim_settings(kind, tomllib.loads("\n".join(block)))


def test_every_section_of_the_loader_is_in_the_example() -> None:
    written = {s.split(".")[0] for s in DOCUMENTED}
    assert set(SECTIONS) - written == set()


def test_each_written_key_has_a_comment() -> None:
    """Beside it, or above it, its short group of keys or their table."""
    lines = EXAMPLE.read_text().splitlines()
    for i, line in enumerate(lines):
        if re.match(r"^\w+\s*=", line):
            j = i
            while j >= 0 and (
                (re.match(r"^\w+\s*=", lines[j]) and "#" not in lines[j])
                or lines[j].startswith("[")
            ):
                j -= 1  # a comment may document a short group of keys, or their table
            assert j >= 0 and "#" in lines[j], f"undocumented key: {line}"
