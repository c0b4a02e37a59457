"""`python -m drake_wbc.cli`: the `drake-wbc` command."""

import sys

from drake_wbc.cli.main import main

sys.exit(main())
