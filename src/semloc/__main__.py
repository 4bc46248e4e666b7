"""`python -m semloc`: the `semloc` command."""

import sys

from semloc.cli import main

sys.exit(main())
