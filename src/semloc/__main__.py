"""`python -m semloc`: the `semloc` command, Ctrl-C honoured from its first moment as by the
`semloc` script (`semloc_entry`; the package's import held the signals already)."""

import sys

from semloc_entry import main

sys.exit(main())
