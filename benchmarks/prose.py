"""Measured figures in prose: inline figures generated from results.json, and the lint that
finds hand-typed ones.

An inline figure is `<!-- fig:PATH|FORMAT -->VALUE<!-- /fig -->`: PATH walks results.json by
`/` (keys may hold dots or spaces; a list takes an index), FORMAT is a Python format spec
(`.3f`, `+.2f`, `,`; omitted: the value as recorded); one in a code span (after a backtick)
is an example, not a figure. `benchmarks.figures.render` rewrites the
VALUE of every inline figure together with the tables, so both come from the same record.

The lint (`measured_figures`, run by `tests/test_prose_figures.py` and by
`python -m benchmarks.figures`): a *figure* is a number followed by a unit of `UNITS` (rates
included); it is *measured* when its sentence (ended by `.`, `!` or `?`; `;` only joins
clauses) holds one of `MEASUREMENT_WORDS`, one of `RESULT_VERBS` with a number right after it
("takes 0.6 s"), one of `CHANGE_VERBS` with "by" and a number after its object ("moved the
distance by 0.1 mm"), or "within NUMBER of" (a table row counts with its header row; a code
block is one sentence). Outside generated regions a measured figure must be
excused by an entry of `docs/figures_allowlist.txt` saying why it is not a measurement of
this code (a setting, a tolerance, a published figure, ...); "unrecorded" (a measurement no
bench records) is refused, so such a figure is generated or goes.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

INLINE = re.compile(r"(?<!`)(<!-- fig:([^|>]+?)(?:\|([^>]*?))? -->)(.*?)(<!-- /fig -->)", re.S)
_BLOCK = re.compile(r"(<!-- figures:\w+ -->\n)(.*?)(<!-- /figures -->)", re.S)

UNITS = (
    *("ms", "µs", "us", "s", "min", "h", "seconds", "minutes", "px", "mm", "cm", "m", "deg"),
    *("°", "%", "fps", "Hz", "kHz", "MB", "KB", "KiB", "MiB", "GB"),
    # rates: a throughput is a figure too ("9.47/min", "8.79 picks per minute", "10 fps")
    *("/min", "/s", "per minute", "per second", "per pick", "picks per minute"),
    *("frames per second",),
)
MEASUREMENT_WORDS = (
    *("measured", "measures", "took", "timed", "found", "median", "mean", "average", "max"),
    *("maximum", "worst", "largest", "rms", "mae", "error", "errors", "latency", "grew"),
    *("std", "p50", "p90", "p95", "p99"),  # σ below: case-sensitive, Σ is a covariance
    # a comparison or a miss is a result: "206x faster", "off by 0.6 px"
    *("faster", "slower", "off by"),
)
# Verbs that state a result only when a number follows them ("takes 0.6 s", "gives 0.170 %",
# "came out at about 70 mm", "drops to 1 %"); alone they are common prose ("takes a cube away",
# "gives the laser plane a third line", "drops the oldest data").
RESULT_VERBS = (
    *("takes", "take", "costs", "cost", "gives", "give", "gave", "reached", "reaches"),
    *("comes out", "came out", "come out", "is at", "drops", "dropped", "falls", "fell"),
    *("rises", "rose", "grows"),
)
# Verbs that state a change by a number after their object: "moved the laser distance by
# 0.1-0.3 mm", "changed it by 0.001 px".
CHANGE_VERBS = ("moved", "shifted", "changed")
_FILLER = r"(?:(?:at|to|from|by|about|only|up to|under|over|around|roughly|nearly|just|~)\s*)*"
REASONS = ("setting", "tolerance", "published", "input", "history")
# Not a reason: a measurement of this code that no bench records is debt, not an excuse. Record
# it in a bench and generate it, or tell the sentence without the number.
REFUSED = {
    "unrecorded": "a measurement of this code that no bench records is not excused: record it in"
    " a bench and generate it with <!-- fig:PATH|FMT -->, or reword the sentence without it"
}

_NUM = r"[-+−]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?"
_UNIT = "|".join(sorted((re.escape(u) for u in UNITS), key=len, reverse=True))
FIGURE = re.compile(rf"(?<![\w.]){_NUM}(?:\s?(?:–|-|…|\.\.\.|/)\s?{_NUM})*\s?(?:{_UNIT})(?![\w])")
_START = r"[-+−]?\d"


def _any(words: tuple[str, ...]) -> str:
    return "(?:" + "|".join(map(re.escape, words)) + ")"


_WORD = re.compile(
    rf"(?<![\w])(?:{_any(MEASUREMENT_WORDS)}(?![\w])|(?-i:σ)"
    # "within 0.002 px of a linear camera's edge": how far a result is from a reference
    rf"|within\s+{_START}[^\s]*(?:\s\S+)?\s+of\b"
    rf"|{_any(RESULT_VERBS)}\s+{_FILLER}{_START}"
    rf"|{_any(CHANGE_VERBS)}\b[^.!?]{{0,40}}?\bby\s+{_FILLER}{_START})",
    re.I,
)
# `;` joins clauses of one sentence ("p95 0.7 px; 1.3 px degraded"): it does not end one
_SPLIT = re.compile(r"(?<!e\.g\.)(?<!i\.e\.)(?<!\bvs\.)(?<=[.!?])\s+")


def lookup(results: dict[str, Any], path: str) -> Any:
    """The value at `path` (`section/key/...`); KeyError names the missing part."""
    value: Any = results
    for part in path.strip().split("/"):
        if isinstance(value, list):
            value = value[int(part)]
        elif isinstance(value, dict) and part in value:
            value = value[part]
        else:
            raise KeyError(f"results.json has no {path!r} (stopped at {part!r})")
    return value


def render_inline(text: str, results: dict[str, Any]) -> str:
    """`text` with the value of every inline figure regenerated from `results`."""

    def one(m: re.Match[str]) -> str:
        value = lookup(results, m.group(2))
        return m.group(1) + format(value, m.group(3) or "") + m.group(5)

    return INLINE.sub(one, text)


def inline_paths(text: str) -> list[str]:
    return [m.group(2).strip() for m in INLINE.finditer(text)]


@dataclass(frozen=True)
class Hit:
    """A measured figure outside the generated regions."""

    path: str
    line: int
    figure: str
    sentence: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.figure!r} in: {self.sentence[:160]}"


@dataclass(frozen=True)
class Entry:
    """One allowlist line: the text around a figure in a file, and why it is no measurement."""

    path: str
    text: str
    reason: str

    def covers(self, hit: Hit) -> bool:
        return self.path == hit.path and hit.figure in self.text and self.text in hit.sentence


def _masked(text: str) -> str:
    """Generated regions, HTML comments and code spans blanked; line breaks kept."""

    def blank(m: re.Match[str]) -> str:
        return m.group(1) + "\n" * m.group(2).count("\n") + m.group(3)

    text = _BLOCK.sub(blank, text)
    text = INLINE.sub(lambda m: "FIG", text)
    text = re.sub(r"<!--.*?-->", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
    return re.sub(r"(?<!`)`[^`\n]+`(?!`)", "CODE", text)


def _units(text: str) -> Iterator[tuple[int, str]]:
    """(first line, text) of every paragraph, list item, table row (with its header row) and
    code block (fenced, or indented four spaces after a blank line)."""
    unit: list[str] = []
    start, header, kind, previous = 0, "", "", ""
    for i, line in enumerate(text.split("\n"), 1):
        stripped = line.strip()
        fence = stripped.startswith("```")
        if (
            kind == "fenced"
            or (fence and not kind)
            or (line.startswith("    ") and (kind == "code" or not previous.strip()))
        ):
            if fence and kind == "fenced":
                yield start, " ".join(unit)
                unit, kind = [], "closed"
            elif kind not in ("fenced", "code"):
                if unit:
                    yield start, " ".join(unit)
                unit, start, kind = [], i, "fenced" if fence else "code"
            if not fence:
                unit.append(stripped)
        else:
            table = stripped.startswith("|")
            item = table or bool(re.match(r"(-|\*|\d+\.)\s", stripped))
            if unit and (not stripped or item or kind):
                yield start, " ".join(unit)
                unit = []
            kind = ""
            if table and not re.fullmatch(r"\|[\s|:-]+\|", stripped):
                header = header if previous.strip().startswith("|") else stripped
                yield i, stripped if header == stripped else f"{header} {stripped}"
            elif stripped and not table:
                start = i if not unit else start
                unit.append(stripped)
        previous = line if kind != "closed" else ""
        kind = "" if kind == "closed" else kind
    if unit:
        yield start, " ".join(unit)


def measured_figures(path: Path, root: Path) -> list[Hit]:
    """Every measured figure of the document outside its generated regions."""
    rel = str(path.relative_to(root))
    hits = []
    for line, unit in _units(_masked(path.read_text(encoding="utf-8"))):
        for sentence in _SPLIT.split(unit):
            if not _WORD.search(sentence):
                continue
            hits += [Hit(rel, line, m.group(0), sentence) for m in FIGURE.finditer(sentence)]
    return hits


def load_allowlist(path: Path) -> list[Entry]:
    """`file | text around the figure | reason: why` lines (the text may hold ` | ` of a table
    row); `#` starts a comment line. A reason outside `REASONS` is a ValueError, `unrecorded`
    with what to do instead."""
    entries = []
    for n, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        parts = [p.strip() for p in raw.split(" | ")]
        reason = parts[-1].split(":", 1)[0].strip()
        if len(parts) >= 3 and reason in REFUSED:
            raise ValueError(f"{path.name}:{n}: {REFUSED[reason]}: {raw!r}")
        if len(parts) < 3 or parts[-1].split(":", 1)[0] not in REASONS:
            raise ValueError(f"{path.name}:{n}: want 'file | text | reason: why', got {raw!r}")
        entries.append(Entry(parts[0], " | ".join(parts[1:-1]), parts[-1]))
    return entries


def check(
    documents: list[Path], root: Path, allowlist: list[Entry]
) -> tuple[list[Hit], list[Entry]]:
    """The measured figures no entry excuses, and the entries that excuse nothing."""
    hits = [h for p in documents for h in measured_figures(p, root)]
    bare = [h for h in hits if not any(e.covers(h) for e in allowlist)]
    unused = [e for e in allowlist if not any(e.covers(h) for h in hits)]
    return bare, unused
