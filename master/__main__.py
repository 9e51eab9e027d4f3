"""`python -m master ...`: the command line."""

import sys

from master.cli import main

sys.exit(main())
