"""``tomllib`` on every supported Python (``tomli`` before 3.11): the one import of it."""

import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["tomllib"]
