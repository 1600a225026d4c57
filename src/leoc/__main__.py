"""``python -m leoc``: the ``leoc`` command."""

import sys

from leoc.cli import main

sys.exit(main())
