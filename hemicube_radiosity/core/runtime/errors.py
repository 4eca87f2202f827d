"""The one family of user-facing errors.

Every problem a user can cause or fix (a setting out of range, a mesh that cannot be cut, a file
that cannot be read, a missing optional package) is a :class:`RadiosityError` whose message is
one line naming the object and the problem. The operator (both paths) and the CLI turn it into the
same one-line message; any other exception is a bug and keeps its traceback.
"""
from __future__ import annotations

__all__ = ["RadiosityError", "SettingsError"]


class RadiosityError(Exception):
    """A user-facing problem: ``str(error)`` is one line that names the object where there is one."""


class SettingsError(RadiosityError, ValueError):
    """A setting outside its choices or limits (also a ValueError, as a bad argument is)."""
