"""`python -m semloc.cli`: the `semloc` command."""

import sys

from semloc.cli import main

sys.exit(main())
