"""Atomic output files (the implementation is ``cnc_interp.outfile``, shared by every stage)."""

from ..outfile import atomic_write, check_writable

__all__ = ["atomic_write", "check_writable"]
