"""Stage packages that are also the API's calls: ``cnc_interp.fit(program)`` and
``cnc_interp.plan(fitted, machine)``.

``cnc_interp.fit`` and ``cnc_interp.plan`` are subpackages, and Python's import system
sets a package's attribute to its subpackage whenever that is imported, so a plain
function of that name in ``cnc_interp`` would be replaced by the module on the first
``import cnc_interp.fit.*``. Instead the subpackage module itself is made callable
(``module.__class__`` may be a ``ModuleType`` subclass); the call is ``api.fit`` /
``api.plan``, and the module is still a module for every import.
"""

from __future__ import annotations

import sys
import types
from typing import Any


class _StageModule(types.ModuleType):
    """A stage package whose call is the API function of the same name."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from . import api

        return getattr(api, self.__name__.rsplit(".", 1)[1])(*args, **kwargs)


def make_callable(module_name: str) -> None:
    """Make the (already imported) package ``module_name`` callable as its API function."""
    sys.modules[module_name].__class__ = _StageModule
