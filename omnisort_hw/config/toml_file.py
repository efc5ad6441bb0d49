"""Reading a TOML file of the product (the cell file, a target description): its table, or a
ConfigError that names the file and what it was meant to be."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from omnisort_hw.errors import ConfigError


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The document of the TOML file `path`, `what` naming it in the errors."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: {what} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the {what} ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc})") from None
