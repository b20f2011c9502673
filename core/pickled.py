"""Frozen slotted records pickled by value: their fields, in order, given back to their class.

A run's rows come back from its worker processes pickled; dataclasses' own ``__setstate__`` for a
slotted class looks its fields up again for every object it restores (a row holds a handful:
poses, its result, its score), and that was most of the time the run's parent spent taking a row.
"""

from __future__ import annotations

import dataclasses


def by_value(cls: type) -> type:
    """Class decorator, outside ``@dataclass(frozen=True, slots=True)``: an instance pickles as
    ``cls(*fields)``. Only for records whose ``__init__`` takes every field and checks nothing."""
    names = tuple(f.name for f in dataclasses.fields(cls))

    def __reduce__(self):
        return cls, tuple(getattr(self, n) for n in names)

    cls.__reduce__ = __reduce__
    return cls
