"""Errors for bad input: the base every layer's input errors share, and the recording
format's own."""

from __future__ import annotations


class InputError(Exception):
    """Bad input (a file's content, a value, a configuration) that the user can fix; the
    message names what and why in one line. The ``exohil`` commands print it as one error
    line with exit status 1, never a traceback."""


class RecordingError(InputError):
    """A recording that cannot be read or written; the message names the file and the problem.

    Raised for files that are not MCAP, truncated or corrupt files, a wrong ``format`` name or
    an unsupported ``version`` in the ``exohil.recording`` metadata, messages that violate the
    v1 schemas, sensor frames with the wrong number of values, and non-increasing ``seq``.
    """
