"""The evaluator's error types."""

from __future__ import annotations


class EvalError(Exception):
    """A problem with one input (named in the message); other inputs are still evaluated."""


class RunStopped(EvalError):
    """A problem no input can get past (the ``--live`` nodes' topics not connected, a lost Dask scheduler): the whole
    run stops, with the message as its one line; the inputs finished before it are kept (with an output folder)."""
