"""``python -m rrr_pin.cli``: the ``rrr-pin`` command."""

import sys

from . import main

sys.exit(main())
