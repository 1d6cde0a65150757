"""``python -m glradial``: the same as the ``glradial`` command."""

import sys

from .cli import main

sys.exit(main())
