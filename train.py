"""``python train.py``: the checkout's way to run ``fdia-train`` (:mod:`agents.train`).

``import train`` gives the module :mod:`agents.train` itself, so the scripts and tests that
import it from the repository root keep working.
"""

import sys

import agents.train

if __name__ == "__main__":
    raise SystemExit(agents.train.cli())
sys.modules[__name__] = agents.train
