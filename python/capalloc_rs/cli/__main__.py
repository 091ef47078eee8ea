"""``python -m capalloc_rs.cli``: the ``capalloc`` command."""

import sys

from .main import main

sys.exit(main())
