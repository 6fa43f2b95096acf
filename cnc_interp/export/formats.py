"""The plan file formats and the name endings that select them (``cnc-interp plan -o``,
``cnc_interp.write``): the one table every writer of a plan consults."""

from __future__ import annotations

from ..outfile import output_format

#: accepted endings of a plan file (any case) and their formats; the first is the default,
#: the format of standard output (``-o -``) and of a device or FIFO
PLAN_FORMATS = {".csv": "csv", ".mcap": "mcap", ".halstream": "halstream"}


def plan_format(path: str) -> str:
    """``"csv"``, ``"mcap"`` or ``"halstream"`` for the plan output ``path``; another
    ending is a ``UsageError`` naming the accepted ones (``outfile.output_format``)."""
    return output_format(path, PLAN_FORMATS, "a plan", stdout="csv")
