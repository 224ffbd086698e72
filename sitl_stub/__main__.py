"""``python -m sitl_stub``: the same as the ``sitl-stub`` command."""

import sys

from sitl_stub.console import main

sys.exit(main())
