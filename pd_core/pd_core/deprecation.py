"""Names kept for one release after a rename (issue 70: what flies around the network is "the
runtime layer", once "the shield"). An old name still works and warns with a `RenamedWarning`
(a `DeprecationWarning`) naming the new one; a console command (`pd-eval`, `pd-train`,
`pd-sweep`) shows each as one line on stderr, once (`show_as_lines`).
"""

from __future__ import annotations

import sys
import warnings
from typing import Any, TypeVar

T = TypeVar("T")


class RenamedWarning(DeprecationWarning):
    """An old name was used: it works until the next release; the message names the new one."""


def renamed(old: str, new: str, stacklevel: int = 2) -> None:
    """Warn that `old` is now `new` (`stacklevel` as `warnings.warn`'s, seen from the caller)."""
    warnings.warn(
        f"{old} is deprecated, use {new} (the old name goes in the next release)",
        RenamedWarning,
        stacklevel=stacklevel + 1,
    )


def renamed_argument(
    where: str, old: str, old_value: T | None, new: str, new_value: T, default: T
) -> T:
    """The value of argument `new` of function `where`, whose old name `old` may be given
    (`old_value` None: not given), which warns (seen from the caller of `where`); ValueError in
    one line where both are given and disagree."""
    if old_value is None:
        return new_value
    renamed(f"{where}({old}=...)", f"{where}({new}=...)", stacklevel=3)
    if new_value != default and new_value != old_value:
        raise ValueError(
            f"{where}: {old}={old_value!r} and {new}={new_value!r} disagree (give only {new}=)"
        )
    return old_value


def show_as_lines(prog: str) -> None:
    """For a console command: each old name used is one line "PROG: ..." on stderr (once per
    place it is read, as Python's "default" action has it)."""
    warnings.simplefilter("default", RenamedWarning)
    shown = warnings.showwarning

    def show(message: Any, category: Any, *args: Any, **kwargs: Any) -> None:
        if issubclass(category, RenamedWarning):
            print(f"{prog}: {message}", file=sys.stderr, flush=True)
        else:
            shown(message, category, *args, **kwargs)

    warnings.showwarning = show
