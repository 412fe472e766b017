"""Shared kernel of the markerplan distribution: version, error roots, provenance.

The four packages of the design (``pipeline``, ``error_model``, ``visibility``, ``planner``)
all import this tiny module, and it imports none of them. It exists so that the two leaf
packages can raise the same error roots without learning about each other.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("markerplan")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
