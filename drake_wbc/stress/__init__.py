"""`drake-wbc stress`: a seeded, randomised stress run of the closed loop.

- cases: the random scenarios, one per case.
- run: the run itself, in processes or on Dask, with its journal.

May import every layer up to the scenarios (drake_wbc.experiments); only
the command line imports it.
"""
