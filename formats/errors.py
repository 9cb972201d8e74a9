"""Errors raised by the recording format readers and writers."""

from __future__ import annotations


class RecordingError(Exception):
    """A recording that cannot be read or written; the message names the file and the problem.

    Raised for files that are not MCAP, truncated or corrupt files, a wrong ``format`` name or
    an unsupported ``version`` in the ``exohil.recording`` metadata, messages that violate the
    v1 schemas, sensor frames with the wrong number of values, and non-increasing ``seq``.
    """
