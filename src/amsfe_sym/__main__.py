"""``python -m amsfe_sym``: the ``amsfe`` command line."""

import sys

from amsfe_sym.apps.cli import main

sys.exit(main())
