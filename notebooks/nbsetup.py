"""What every notebook starts with: matplotlib on the Agg backend, the folder its figures go to,
and one way to save a figure there.

Figures go to ``$MARKERPLAN_NB_OUT``, else to a fresh temporary folder, never into the
repository or the working folder. Import this first: ``from nbsetup import OUT, plt, save``.
"""

import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

#: The folder figures go to.
OUT = Path(os.environ.get("MARKERPLAN_NB_OUT") or tempfile.mkdtemp(prefix="markerplan-nb-"))
OUT.mkdir(parents=True, exist_ok=True)
print("figures ->", OUT)


def save(fig, name: str, dpi: int = 90) -> Path:
    """Save ``fig`` as ``OUT / name`` and close it; return the path."""
    path = OUT / name
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


__all__ = ["OUT", "plt", "save"]
