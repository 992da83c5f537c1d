"""``python -m grutrack``: the same as the ``grutrack`` console script."""

import sys

from grutrack.cli import main

sys.exit(main())
