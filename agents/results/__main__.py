"""``python -m agents.results``."""

from agents.results.cli import main

raise SystemExit(main())
