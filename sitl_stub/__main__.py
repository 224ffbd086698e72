"""``python -m sitl_stub``: the same as the ``sitl-stub`` command."""

import sys

from sitl_stub.cli import main

sys.exit(main())
