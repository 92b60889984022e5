"""TOML: ``tomllib`` on every supported Python (``tomli`` before 3.11: the one import of it),
and the small writer of ``config.toml``."""

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from amsfe_sym.errors import AmsfeError, ConfigError, describe

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["dump_toml", "read_toml", "tomllib"]


def read_toml(path: Path, error: type[AmsfeError]) -> dict[str, Any]:
    """Parse the TOML file ``path``; an unreadable, non-UTF-8 or malformed file raises
    ``error`` with one line (the robot spec, scenario, sweep and log spec readers share it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            describe(str(path), "a UTF-8 text file", f"byte {exc.start} not UTF-8", "save as UTF-8")
        ) from exc
    except OSError as exc:
        raise error(describe(str(path), "a readable file", str(exc), "check the path")) from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc}). Fix: correct the syntax.") from exc


def dump_toml(data: Mapping[str, Any]) -> str:
    """Write nested dicts of scalars, strings and lists as TOML (enough for ``config.toml``)."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int | float):
            return repr(float(v)) if isinstance(v, float) else str(v)
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list | tuple):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, Mapping):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        raise ConfigError(f"cannot write {type(v).__name__} to TOML")

    # None is "not set" (e.g. [camera] delay = the robot's): the key is left out
    lines = [
        f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, Mapping) and v is not None
    ]
    for k, v in data.items():
        if isinstance(v, Mapping):
            lines.append(f"\n[{k}]")
            lines.extend(f"{kk} = {value(vv)}" for kk, vv in v.items() if vv is not None)
    return "\n".join(lines) + "\n"
