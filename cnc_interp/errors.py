"""One exception hierarchy for the whole tool.

Every error a user can cause (bad G-code, bad machine file, bad option) is a
``CncInterpError`` carrying a source location, so the CLI can print exactly one
``FILE:LINE:COL: error: MESSAGE`` line and exit with ``exit_code``.
Expected planner outcomes (e.g. a limit that cannot be met) are statuses on
results, not exceptions; ``PlanError`` is for a plan that failed outright.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SourceLocation:
    """Where in an input file something happened (1-based line and column)."""

    file: str = "cnc-interp"  # no file: errors read "cnc-interp: error: ..."
    line: int = 0
    col: int = 0
    text: str = ""  # the offending source text, quoted in the message when present

    def prefix(self) -> str:
        if self.line > 0:
            return f"{self.file}:{self.line}:{max(self.col, 1)}"
        return f"{self.file}"


class CncInterpError(Exception):
    """Base of all errors the tool reports to its user."""

    exit_code = 2

    def __init__(self, message: str, location: SourceLocation | None = None):
        super().__init__(message)
        self.message = message
        self.location = location or SourceLocation()

    def format(self) -> str:
        """The one-line ``FILE:LINE:COL: error: MESSAGE`` form the CLI prints."""
        msg = self.message
        text = self.location.text
        if text:
            if len(text) > 60:
                text = text[:57] + "..."
            msg = f"{msg}: '{text}'"
        return _printable(f"{self.location.prefix()}: error: {msg}")

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.format()

    def in_file(self, name: str) -> "CncInterpError":
        """This error, or where it names no place (a planner's), the same one naming ``name``."""
        if self.location.line or self.location.file != SourceLocation().file:
            return self
        return type(self)(self.message, SourceLocation(file=name))


_CONTROL = {c: f"\\x{c:02x}" for c in (*range(0x20), 0x7F)}
_CONTROL_BUT_LINES = {c: v for c, v in _CONTROL.items() if c not in (0x09, 0x0A)}


def _printable(text: str) -> str:
    """``text`` with control characters (ESC, BEL, CR, ...) escaped as ``\\xNN``: a file
    name or source text must not drive the user's terminal."""
    return text.translate(_CONTROL)


def printable(text: str, lines: bool = False) -> str:
    """``text`` as it may reach a terminal: control characters escaped as ``\\xNN``
    (a machine's name or a file name holding ESC or BEL must not drive the terminal);
    with ``lines``, newlines and tabs are kept (a multi-line summary)."""
    return text.translate(_CONTROL_BUT_LINES if lines else _CONTROL)


class CncInterpWarning(UserWarning):
    """Something the user should know that does not stop the run; its text is one
    ``FILE:LINE:COL: warning: ...`` line (the CLI prints just that)."""


class GCodeError(CncInterpError):
    """Malformed or unsupported G-code (location = file, line, column, text)."""


class UnsupportedError(GCodeError):
    """A valid RS274NGC construct this tool does not implement; names the construct."""


class MachineError(CncInterpError):
    """Bad machine description (TOML/INI/preset): missing axis, bad limit, unknown key."""


class UsageError(CncInterpError):
    """Bad command-line usage that click itself cannot detect."""


class PlanError(CncInterpError):
    """A plan that could not be produced or that failed verification (exit 1)."""

    exit_code = 1


class FitError(CncInterpError):
    """A fitted path that misses its tolerance where the fit could not repair it (exit 1):
    the command fails rather than plan a path outside the part; names the source line."""

    exit_code = 1


class OutputError(CncInterpError):
    """An output that could not be written for a reason the input did not cause (a full
    disk); the previous file is kept (exit 1)."""

    exit_code = 1


class DeviceError(CncInterpError):
    """USB device failure: disconnect, repeated CRC errors, protocol violation (exit 1)."""

    exit_code = 1
