"""``agents.leaderboard.render`` under its checkout name: the same module object."""

import sys

import agents.leaderboard.render

sys.modules[__name__] = agents.leaderboard.render
