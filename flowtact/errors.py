"""The one base of every error flowtact raises on purpose: ``except FlowtactError`` catches them all.

Each public error also keeps the built-in base that says what kind of mistake it is (a bad value
is a ``ValueError``, an unknown name a ``LookupError``, a failed run a ``RuntimeError``).
"""

from __future__ import annotations

__all__ = ["FlowtactError", "UsageError"]


class FlowtactError(Exception):
    """Base class of flowtact's errors: bad configs, graphs, streams, data, devices and runs."""


class UsageError(FlowtactError, ValueError):
    """Bad usage or bad input named on the command line (a flag's value, a file the user gave):
    the command refuses it before doing its work, with one line and exit status 2."""
