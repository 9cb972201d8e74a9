"""exohil: hardware-in-the-loop harness and conformance suite for a soft shoulder exosuit."""

__version__ = "0.1.0"
