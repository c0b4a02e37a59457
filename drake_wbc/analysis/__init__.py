"""Analysis of the controller: frequency responses of its linearisations.

- frequency: H(j omega) or H(e^(j omega h)) from A, B, C, D; bandwidth,
  peak gain, gain and phase margins.
- closed_forms: eqs. (lp-admit) and (tf-admit) and their exact
  zero-order-hold equivalents (eq. (filtering)'s are in
  drake_wbc.math.filtering).
- chains: the filter chain built from the project's systems and
  linearised with Drake; dmp_force_response: the coupled DMPs' force
  responses, likewise; plant_chain: the station's base driver and plant
  around their static equilibrium; period_map: the AutoDiff
  linearisation of a multi-rate diagram over one control period.
- bode, report: Bode plots, CSV files and the table (the `drake-wbc
  bode` command is in drake_wbc.cli.analysis).

Above the scenarios (drake_wbc.experiments), which it analyses; below the
command line.
"""
