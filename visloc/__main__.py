"""``python -m visloc``: the ``visloc`` command (:func:`visloc.cli.main`)."""

import sys

from visloc.cli import main

sys.exit(main())
