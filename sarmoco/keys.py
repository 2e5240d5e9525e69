"""Declaration of a configuration key: a dataclass field with its documentation and bounds.

Any layer may declare settings this way (the daemon's configuration sections, the
autofocus settings of ``processing``); the daemon's loader (``daemon/config.py``) reads
the metadata to check values and to write the key table of docs/configuration.md, so a
key's meaning, unit and limits live beside its default.
"""

from __future__ import annotations

from dataclasses import field
from typing import Any


def key(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    gt: float | None = None,
    ge: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: tuple[str, ...] = (),
    refused: tuple[tuple[Any, str], ...] = (),
) -> Any:
    """Declare a config key with its documentation, numeric bounds or allowed strings.

    Parameters
    ----------
    default : Any
        The value when the key is not given (immutable: no list or dict).
    doc : str
        One-sentence meaning of the key (the key table's last column).
    unit : str
        Physical unit of the value, e.g. ``"s"``, ``"m"``; empty for counts and flags.
    gt, ge, le, lt : float or None
        Bounds the loader enforces (``>``, ``>=``, ``<=``, ``<``).
    choices : tuple of str
        Allowed values of a string key whose values come from a registry (a ``Literal``
        type states fixed ones).
    refused : tuple of (value, reason)
        Values of the type that the loader refuses with their reason (a value that would
        parse but gives a wrong product).

    Returns
    -------
    dataclasses.Field
        The field, typed ``Any`` so that it can stand as a dataclass default.

    Raises
    ------
    TypeError
        If ``default`` is mutable.
    """
    meta = {
        "doc": doc,
        "unit": unit,
        "gt": gt,
        "ge": ge,
        "le": le,
        "lt": lt,
        "choices": choices,
        "refused": dict(refused),
    }
    if isinstance(default, list | dict):
        raise TypeError("mutable defaults are not allowed in config sections")
    return field(default=default, metadata=meta)
