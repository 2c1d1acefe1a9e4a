"""``python -m rrr_pin.cli``: the ``rrr-pin`` command."""

import sys

from . import main

if __name__ == "__main__":  # not on import (the API reference imports every module)
    sys.exit(main())
