"""Old keyword spellings kept for one release: they still work, with a ``DeprecationWarning``."""

from __future__ import annotations

import functools
import warnings
from typing import Callable

__all__ = ["renamed_keywords"]


def renamed_keywords(**renames: str) -> Callable:
    """Decorator: accept each old keyword ``old=new`` as an alias of ``new`` for one release.

    Passing the old spelling warns with a ``DeprecationWarning`` that names the new one; passing both is a
    ``TypeError``.

    Example
    -------
    >>> @renamed_keywords(model="muscle_model")
    ... def solve(*, muscle_model="cable"):
    ...     return muscle_model
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     solve(model="springs"), w[0].category.__name__
    ('springs', 'DeprecationWarning')
    """

    def wrap(fn: Callable) -> Callable:
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            for old, new in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{fn.__name__}() got both {old}= (deprecated) and {new}=; pass {new}= only")
                    warnings.warn(f"{fn.__name__}(): the keyword {old}= is deprecated and will be removed in the "
                                  f"next release; use {new}=", DeprecationWarning, stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return fn(*args, **kwargs)

        inner.__renamed_keywords__ = dict(renames)
        return inner

    return wrap
