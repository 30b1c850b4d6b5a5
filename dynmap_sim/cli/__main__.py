"""``python -m dynmap_sim.cli``: the ``dynmap-sim`` command line."""

import sys

from dynmap_sim.cli import main

sys.exit(main())
