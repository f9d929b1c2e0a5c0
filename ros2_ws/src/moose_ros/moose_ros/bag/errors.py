"""The error of the bag tools."""


class BagError(RuntimeError):
    """A bag cannot be written or read; the message says which path and why."""
