"""The evaluator's error type."""

from __future__ import annotations


class EvalError(Exception):
    """A problem with one input (named in the message); other inputs are still evaluated."""
