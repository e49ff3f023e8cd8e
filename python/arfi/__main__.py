"""``python -m arfi``: the command line."""

import sys

from arfi.cli import main

sys.exit(main())
