"""Where casecal keeps what it makes for itself: compiled kernels, the register of written files."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """Where compiled kernels live: ``$CASECAL_CACHE``, else ``~/.cache/casecal``.

    Always an absolute path: dlopen searches the library path, not the working folder, for
    a name without a slash (``CASECAL_CACHE=.`` built kernels it then could not load).
    """
    folder = os.environ.get("CASECAL_CACHE") or str(Path.home() / ".cache" / "casecal")
    return Path(os.path.abspath(os.path.expanduser(folder)))
