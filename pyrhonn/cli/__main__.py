"""``python -m pyrhonn.cli``: the same as the ``pyrhonn`` console script."""
import sys

from . import main

sys.exit(main())
