"""Checks on configuration values shared by the settings dataclasses."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from markerplan.errors import ConfigError


def require_non_negative(settings: object, names: Iterable[str], label: str = "") -> None:
    """Refuse any of the fields ``names`` of ``settings`` that is not a finite number >= 0.

    Parameters
    ----------
    settings : object
        A settings dataclass (read with ``getattr``).
    names : iterable of str
        Fields to check.
    label : str
        Prefix of the field's name in the message, e.g. ``"turntable "``.

    Raises
    ------
    ConfigError
        ``"<label><name> must be a number >= 0, got <value>"``.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> require_non_negative(SimpleNamespace(a=0.0, b=2), ("a", "b"))
    >>> require_non_negative(SimpleNamespace(wobble_rad=-1.0), ["wobble_rad"], "turntable ")
    Traceback (most recent call last):
    ...
    markerplan.errors.ConfigError: turntable wobble_rad must be a number >= 0, got -1.0
    """
    for name in names:
        value = getattr(settings, name)
        if not (isinstance(value, int | float) and np.isfinite(value) and value >= 0):
            raise ConfigError(f"{label}{name} must be a number >= 0, got {value!r}")
