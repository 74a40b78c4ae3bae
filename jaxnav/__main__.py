"""``python -m jaxnav`` runs the command line."""

import sys

from jaxnav.cli import main

sys.exit(main())
