"""``python -m baselines.reproduce CHAPTER``."""

from baselines.reproduce.cli import main

raise SystemExit(main())
