"""``python -m handrig.cli``: the same as the ``handrig`` command."""

import sys

from handrig.cli import main

sys.exit(main())
