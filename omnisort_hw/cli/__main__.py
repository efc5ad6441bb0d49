"""`python -m omnisort_hw.cli` runs the command line (the tests use it)."""

import sys

from omnisort_hw.cli import main

sys.exit(main())
