"""The error every check of user input raises: :class:`ParamError`, whose message names the field and the value.

It stands in a module of its own so that both the parameter loader (:mod:`moose.params`) and the input-file reader
(:mod:`moose.files`), which the loader calls, can raise it without importing each other.
"""
from __future__ import annotations


class ParamError(ValueError):
    """A parameter (file) is invalid; the message names the field and the value."""
