"""A module imported on first use, for the modules on ``imulog info``'s path.

``imulog info`` reads only the summary and the metadata records, so it needs neither numpy nor anything that
imports it; importing numpy alone is 0.06-0.2 s, a third or more of the command. The archive reader, the
metadata codec, the time axis and the stream types use numpy only inside functions, so they bind ``np`` to a
:class:`LazyModule`: the first attribute looked up imports the real module and rebinds the owner's global to it,
after which there is no indirection at all.

    np = LazyModule("numpy", __name__)   # instead of: import numpy as np
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import Any


class LazyModule:
    """Stand-in for module ``name`` in module ``owner``'s globals until its first attribute is looked up."""

    def __init__(self, name: str, owner: str) -> None:
        self._name = name
        self._owner = owner

    def _load(self) -> ModuleType:
        module = importlib.import_module(self._name)
        owner = sys.modules.get(self._owner)
        if owner is not None:
            for key in [k for k, v in vars(owner).items() if v is self]:
                setattr(owner, key, module)
        return module

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._load(), attr)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r} for {self._owner}>"
