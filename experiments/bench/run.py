"""``agents.leaderboard.run`` under its checkout name: the same module object."""

import sys

import agents.leaderboard.run

sys.modules[__name__] = agents.leaderboard.run
