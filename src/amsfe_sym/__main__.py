"""``python -m amsfe_sym``: the ``amsfe`` command line."""

import sys

try:
    from amsfe_sym.apps.cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line's modules load: one line
    print(
        "interrupted: amsfe stopped by Ctrl-C while starting; nothing was written", file=sys.stderr
    )
    sys.exit(130)

sys.exit(main())
