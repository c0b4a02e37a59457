"""The `drake-wbc` command line.

- main: the command and its subcommands (`SUBCOMMANDS`).
- analysis: `drake-wbc bode` and `drake-wbc diagram`.
- hardware: `drake-wbc robot-sim`, `deploy` and `plot`.
- teach: `drake-wbc teach` and `drake-wbc replay`.
- model_report: `drake-wbc demo`'s report of the robot model.

The top layer: it may import every other; nothing imports it.
"""
