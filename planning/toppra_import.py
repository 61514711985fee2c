"""toppra, imported without matplotlib.

toppra's package imports matplotlib.pyplot (in ``toppra.algorithm.algorithm`` and ``toppra.parametrizer``) for
plotting methods the planner never calls: ~0.3 s of every ``plan`` and ``compare`` process, whose figures are
drawn in a figure worker (:func:`planning.figures.figure_worker`) that imports matplotlib itself. While toppra
loads, ``matplotlib`` and ``matplotlib.pyplot`` are stand-in modules; a stand-in imports the real module at the
first use of one of its names (toppra's ``plt.plot`` would still work), and after the import they are gone from
``sys.modules``, so a later ``import matplotlib.pyplot`` gets the real one. Where matplotlib is loaded already
(a test session), toppra is imported plainly.
"""
from __future__ import annotations

import importlib
import sys
import types


class _StandIn(types.ModuleType):
    """A module that imports the real one of its name at the first use of a name it lacks."""

    def __getattr__(self, name: str):
        if name.startswith("__"):  # the import system's own look-ups (__path__, ...): not a use
            raise AttributeError(name)
        if sys.modules.get(self.__name__) is self:
            del sys.modules[self.__name__]
        return getattr(importlib.import_module(self.__name__), name)


def _load():
    if "matplotlib" in sys.modules or "toppra" in sys.modules:
        import toppra
        import toppra.algorithm

        return toppra
    mpl, pyplot = _StandIn("matplotlib"), _StandIn("matplotlib.pyplot")
    mpl.pyplot = pyplot  # `import matplotlib.pyplot as plt` takes the attribute of the package
    stand_ins = {"matplotlib": mpl, "matplotlib.pyplot": pyplot}
    sys.modules.update(stand_ins)
    try:
        import toppra
        import toppra.algorithm
    finally:
        for name, mod in stand_ins.items():
            if sys.modules.get(name) is mod:
                del sys.modules[name]
    return toppra


toppra = _load()
