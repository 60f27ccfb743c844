"""``python -m spslidar``: the ``spslidar`` command (:func:`spslidar.cli.main`)."""

import sys

from .cli import main

sys.exit(main())
