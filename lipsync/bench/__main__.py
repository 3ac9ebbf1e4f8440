"""``python -m lipsync.bench``."""

import sys

from . import main

sys.exit(main())
