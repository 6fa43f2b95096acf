"""RS274NGC parameters: numbered ``#1..#5601`` and named ``#<name>`` / ``#<_global>``.

Semantics follow LinuxCNC:

* numbered parameters are floats that read as 0.0 until set; a number outside
  ``1..PARAM_NUMBERED_MAX`` is an error;
* a named parameter read before it is set is an error naming it;
* names are lower case without spaces (the lexer normalises them); a name that
  starts with ``_`` is global, any other name is local to the current O-word call
  frame (the main program being frame 0);
* ``#1..#30`` are local to an O-word call: :meth:`ParamStore.push_frame` saves
  them and loads the call's arguments, :meth:`ParamStore.pop_frame` restores them;
* ``#<_value>`` / ``#<_value_returned>`` (the last O-word return value and whether
  there was one) start at 0.
"""

from __future__ import annotations

from ..constants import PARAM_LOCAL_COUNT, PARAM_NUMBERED_MAX
from ..errors import GCodeError, SourceLocation


class ParamStore:
    """Numbered and named parameters, with O-word call frames."""

    __slots__ = ("numbered", "globals", "locals", "_frames")

    def __init__(self) -> None:
        # index 0 is unused so that #n is numbered[n]
        self.numbered: list[float] = [0.0] * (PARAM_NUMBERED_MAX + 1)
        # LinuxCNC starts a program with the O-word return value at 0
        self.globals: dict[str, float] = {"_value": 0.0, "_value_returned": 0.0}
        self.locals: dict[str, float] = {}
        self._frames: list[tuple[list[float], dict[str, float]]] = []

    # -- access ---------------------------------------------------------------
    def get(self, key: int | str, loc: SourceLocation | None = None) -> float:
        """Value of ``#key``; ``key`` is an int (numbered) or a lower-case name."""
        if key.__class__ is int:
            if 0 < key <= PARAM_NUMBERED_MAX:  # type: ignore[operator]
                return self.numbered[key]  # type: ignore[index]
            raise GCodeError(f"parameter number #{key} out of range 1..{PARAM_NUMBERED_MAX}", loc)
        d = self.globals if key[0] == "_" else self.locals  # type: ignore[index]
        try:
            return d[key]  # type: ignore[index]
        except KeyError:
            raise GCodeError(f"undefined parameter #<{key}>", loc) from None

    def set(self, key: int | str, value: float, loc: SourceLocation | None = None) -> None:
        """Set ``#key`` to ``value``."""
        if key.__class__ is int:
            if 0 < key <= PARAM_NUMBERED_MAX:  # type: ignore[operator]
                self.numbered[key] = float(value)  # type: ignore[index]
                return
            raise GCodeError(f"parameter number #{key} out of range 1..{PARAM_NUMBERED_MAX}", loc)
        if not key:
            raise GCodeError("empty parameter name #<>", loc)
        if key[0] == "_":  # type: ignore[index]
            self.globals[key] = float(value)  # type: ignore[index]
        else:
            self.locals[key] = float(value)  # type: ignore[index]

    def exists(self, key: int | str) -> bool:
        """True if ``#key`` can be read (numbered parameters in range always exist)."""
        if key.__class__ is int:
            return 0 < key <= PARAM_NUMBERED_MAX  # type: ignore[operator]
        if not key:
            return False
        return key in (self.globals if key[0] == "_" else self.locals)  # type: ignore[index]

    # -- O-word call frames ---------------------------------------------------
    @property
    def depth(self) -> int:
        """Number of O-word calls currently active (0 in the main program)."""
        return len(self._frames)

    def push_frame(self, args: list[float]) -> None:
        """Enter an O-word call: save #1..#30 and the local names, load ``args``."""
        n = PARAM_LOCAL_COUNT
        num = self.numbered
        self._frames.append((num[1 : n + 1], self.locals))
        num[1 : n + 1] = [float(a) for a in args[:n]] + [0.0] * (n - min(len(args), n))
        self.locals = {}

    def pop_frame(self) -> None:
        """Leave an O-word call: restore the caller's #1..#30 and local names."""
        saved, names = self._frames.pop()
        self.numbered[1 : PARAM_LOCAL_COUNT + 1] = saved
        self.locals = names
