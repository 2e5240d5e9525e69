"""The check every configuration-refusal test makes: the error text, from its start."""

from __future__ import annotations

import pytest

from sarmoco.daemon.config import parse_config
from sarmoco.errors import ConfigError


def assert_refused(table: dict[str, object], message: str) -> None:
    """:func:`parse_config` refuses ``table`` with a :class:`ConfigError` that begins
    with ``message`` (the key path, the bad value and the rule it breaks)."""
    with pytest.raises(ConfigError) as info:
        parse_config(table)
    assert str(info.value).startswith(message), str(info.value)
