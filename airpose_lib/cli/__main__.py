"""``python -m airpose_lib.cli`` = ``python -m airpose_lib`` = the ``airpose`` command."""

import sys

from airpose_lib.cli import main

sys.exit(main())
