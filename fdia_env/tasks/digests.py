"""SHA-256 of the stored benchmark data, checked when it is read (fdia_env.tasks.stored).

Written by ``python -m agents.bench compute`` and ``python -m agents.bench payoff``
together with the files: do not edit by hand.
"""

REFERENCES = "1c0d24d83632e9485a969bab5d0546a177621bee145cb7d68e3d81d65f025b46"
PAYOFF_MANIFEST = "f5a083ffd090a3f920cc8bc27607c73a50862eaf7190ea1c4e82c048120b1fcb"
PAYOFF_FILES = {
    "grid-ieee118-independent-k1-a0.01.npy": "058a25d5098f9778398c6aaf59eb7cb8f7d3581a107dc7c53b648d23f3719811",  # noqa: E501
}
