"""``python -m meshmocap.cli``: the ``meshmocap`` command."""

import sys

from meshmocap.cli import main

sys.exit(main())
