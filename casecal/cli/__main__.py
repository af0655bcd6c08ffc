"""``python -m casecal.cli``: the ``casecal`` command."""

import sys

from .._entry import main

sys.exit(main())
