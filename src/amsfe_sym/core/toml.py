"""TOML: ``tomllib`` on every supported Python (``tomli`` before 3.11: the one import of it),
and the small writer of ``config.toml``."""

import sys
from collections.abc import Mapping
from typing import Any

from amsfe_sym.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["dump_toml", "tomllib"]


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
