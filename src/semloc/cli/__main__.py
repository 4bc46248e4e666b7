"""`python -m semloc.cli`: the `semloc` command, as `python -m semloc`."""

import sys

from semloc_entry import main

sys.exit(main())
