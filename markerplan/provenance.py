"""Provenance block written into every output file.

Deliberately free of timestamps and host names: the same inputs and seed must give
byte-identical outputs.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from markerplan import __version__


def provenance(config: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """Return the provenance record for an output.

    Parameters
    ----------
    config : dict
        The fully resolved configuration (JSON-serialisable).
    **extra
        Further fields, e.g. ``solver={"name": "highs", "status": "optimal"}``.

    Returns
    -------
    record : dict
        ``{"markerplan_version", "config", "config_sha256", **extra}``.

    Examples
    --------
    >>> p = provenance({"seed": 1})
    >>> sorted(p)
    ['config', 'config_sha256', 'markerplan_version']
    """
    blob = json.dumps(config, sort_keys=True, default=str).encode()
    return {
        "markerplan_version": __version__,
        "config": config,
        "config_sha256": hashlib.sha256(blob).hexdigest(),
        **extra,
    }


def fingerprint_arrays(*arrays: Any) -> str:
    """SHA-256 over the bytes, dtypes and shapes of numpy arrays (data fingerprint)."""
    import numpy as np

    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()
