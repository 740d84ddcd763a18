"""The package's version and the versions a result records (a leaf: imports nothing of the package)."""

from __future__ import annotations

import platform

import numpy as np

__all__ = ["__version__", "versions"]

__version__ = "0.1.0"


def versions() -> dict:
    """flexmech's, Python's, numpy's and scipy's versions and the platform, as a result records them."""
    import scipy   # start-up time: scipy is only needed when a result is written

    return {"flexmech": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "platform": platform.platform()}
