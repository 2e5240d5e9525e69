"""``python -m sarmoco``: the command line."""

from __future__ import annotations

import sys

from sarmoco.app.cli import main

sys.exit(main())
