"""Bode plots, CSV files and the summary table of frequency responses.

A `BodePlot` is one figure: curves sharing one frequency grid, drawn as
magnitude (dB) over phase (degrees) against a logarithmic frequency in Hz,
with rad/s on a secondary axis, and written alongside as a CSV file with
a header. A `ResponseSummary` is one row of the printed table: the DC
gain, the -3 dB bandwidth, the peak gain and, for a loop, the margins.
"""

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drake_wbc.analysis.frequency import (
    bandwidth,
    dc_gain,
    decibels,
    low_frequency_power,
    peak_gain,
    phase_degrees,
)
from drake_wbc.math.validation import as_vector

TWO_PI = 2.0 * np.pi


@dataclass
class BodeCurve:
    """One response on a BodePlot.

    Attributes:
        label: the legend's text and the CSV columns' prefix.
        response: (N,) complex response on the plot's grid.
        closed_form: True draws it dashed (a closed form drawn over the
            linearisation it checks).
        family: None, or (colour index, line style) for a family of
            curves over two parameters (one colour per value of the
            first, one line style per value of the second).
    """

    label: str
    response: np.ndarray
    closed_form: bool = False
    family: tuple | None = None


@dataclass
class BodePlot:
    """One figure and its CSV file.

    Attributes:
        name: the files' stem (name.png, name.csv).
        title: the figure's title.
        hertz: (N,) increasing frequencies in Hz, shared by the curves.
        curves: the BodeCurves.
        nyquist_hz: the Nyquist frequency of a discrete chain, marked on
            the plot (None for none).
    """

    name: str
    title: str
    hertz: np.ndarray
    curves: list[BodeCurve] = field(default_factory=list)
    nyquist_hz: float | None = None

    def add(self, label, response, closed_form=False, family=None):
        """Adds a curve (checked to match the grid) and returns it."""
        response = np.asarray(response, dtype=complex).ravel()
        if response.shape != np.shape(self.hertz):
            raise ValueError(
                f"response of {label!r} has shape {response.shape}, which "
                f"is not allowed: must match the grid, {np.shape(self.hertz)}")
        curve = BodeCurve(label, response, closed_form, family)
        self.curves.append(curve)
        return curve


def _unwrapped(response):
    """Phase in degrees, unwrapped, shifted by whole turns to start in
    (-180, 180]."""
    phase = phase_degrees(response)
    turns = np.round(phase[0] / 360.0)
    return phase - 360.0 * turns


def write_csv(plot, folder):
    """Writes folder/<name>.csv: frequency_hz, omega_rad_s, then
    '<label> magnitude_db' and '<label> phase_deg' per curve. Returns the
    path."""
    path = Path(folder) / f"{plot.name}.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    hertz = as_vector("hertz", plot.hertz)
    columns = [hertz, TWO_PI * hertz]
    header = ["frequency_hz", "omega_rad_s"]
    for curve in plot.curves:
        header += [f"{curve.label} magnitude_db", f"{curve.label} phase_deg"]
        columns += [decibels(curve.response), _unwrapped(curve.response)]
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        for row in np.column_stack(columns):
            writer.writerow([f"{v:.10g}" for v in row])
    return path


def read_csv(path):
    """(header, (N, columns) float array) of a CSV written by write_csv."""
    with Path(path).open(newline="") as stream:
        rows = list(csv.reader(stream))
    return rows[0], np.array(rows[1:], dtype=float)


def draw(plot, folder):
    """Draws `plot` as folder/<name>.png (Bode layout) and returns the
    path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from drake_wbc.experiments.common import save_figure

    fig, (magnitude, phase) = plt.subplots(2, 1, sharex=True,
                                           figsize=(8.0, 6.0))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    measured = 0
    for curve in plot.curves:
        if curve.closed_form:
            style = dict(color="black", linestyle="--", linewidth=1.0)
        elif curve.family is not None:
            colour, linestyle = curve.family
            style = dict(color=colours[colour % len(colours)],
                         linestyle=linestyle, linewidth=1.4)
        else:
            style = dict(color=colours[measured % len(colours)],
                         linewidth=1.6)
            measured += 1
        magnitude.semilogx(plot.hertz, decibels(curve.response),
                           label=curve.label, **style)
        phase.semilogx(plot.hertz, _unwrapped(curve.response), **style)
    magnitude.axhline(-3.0, color="grey", linewidth=0.6, linestyle=":")
    for axis in (magnitude, phase):
        axis.grid(True, which="both", alpha=0.3)
        if plot.nyquist_hz is not None:
            axis.axvline(plot.nyquist_hz, color="grey", linewidth=0.8,
                         linestyle="-.")
    magnitude.set_ylabel("magnitude (dB)")
    phase.set_ylabel("phase (deg)")
    phase.set_xlabel("frequency (Hz)")
    top = magnitude.secondary_xaxis(
        "top", functions=(lambda f: TWO_PI * f, lambda w: w / TWO_PI))
    top.set_xlabel("angular frequency (rad/s)")
    magnitude.set_xlim(plot.hertz[0], plot.hertz[-1])
    magnitude.legend(fontsize=7, loc="best")
    fig.suptitle(plot.title, fontsize=10)
    path = save_figure(fig, folder, plot.name)
    plt.close(fig)
    return path


@dataclass
class ResponseSummary:
    """One row of the table.

    Attributes:
        name: the response's name.
        dc_gain_db: the DC gain, dB (frequency.dc_gain: the gain at the
            grid's lowest frequency where the response is flat there;
            inf for a pole at DC, an integrator; -inf for a zero there;
            nan where a pole or zero near the grid's lowest frequency
            hides it).
        bandwidth_hz: where the gain has fallen 3 dB below it, Hz (nan if
            it never does on the grid, or the DC gain is not finite and
            nonzero).
        peak_db, peak_hz: the largest gain on the grid and where; inf at
            0 Hz for a pole at DC, whose gain grows without bound
            towards DC; nan where the gain still rises at the grid's
            lowest frequency and is largest there (its peak lies below
            the band).
        gain_margin_db, phase_margin_deg: of a loop (nan where no loop
            closes or it has no margins; inf where |L| or the phase
            never crosses).
        stable_gain: the largest stable value of a loop's gain (the
            admittance loop's k_hri), nan where none is computed; the
            table and summary.csv have this column only if some row has
            one.
        margins_unavailable: why a loop has no margins (e.g. "open loop
            unstable: |z| = 1.102 at 38.6 Hz"), "" where it has them or
            is no loop; the table shows its margins as n/a, and
            summary.csv has this column only if some row has one.
    """

    name: str
    dc_gain_db: float
    bandwidth_hz: float
    peak_db: float
    peak_hz: float
    gain_margin_db: float = float("nan")
    phase_margin_deg: float = float("nan")
    stable_gain: float = float("nan")
    margins_unavailable: str = ""


def summarize(name, hertz, response, margins=None, stable_gain=None,
              margins_unavailable=""):
    """The ResponseSummary of `response` on the grid `hertz` (Hz), with
    the StabilityMargins `margins` of its loop if any, or the reason
    `margins_unavailable` why its loop has none."""
    if margins is not None and margins_unavailable:
        raise ValueError(
            f"margins_unavailable = {margins_unavailable!r} is not allowed "
            "with margins: must be '' where the loop has them")
    omega = TWO_PI * as_vector("hertz", hertz)
    response = np.asarray(response)
    peak, at = peak_gain(omega, response)
    dc = dc_gain(omega, response)
    if np.isinf(dc):
        peak, at = dc, 0.0
    elif np.isnan(dc) and at == omega[0] and low_frequency_power(
            omega, response) < 0.0:
        peak = at = float("nan")
    return ResponseSummary(
        name=name,
        dc_gain_db=float(decibels(dc)),
        bandwidth_hz=bandwidth(omega, response) / TWO_PI,
        peak_db=float(decibels(peak)),
        peak_hz=at / TWO_PI,
        gain_margin_db=(margins.gain_margin_db if margins is not None
                        else float("nan")),
        phase_margin_deg=(margins.phase_margin if margins is not None
                          else float("nan")),
        stable_gain=(float("nan") if stable_gain is None
                     else float(stable_gain)),
        margins_unavailable=str(margins_unavailable))


TABLE_COLUMNS = (
    ("response", "name", "{}"),
    ("DC (dB)", "dc_gain_db", "{:.2f}"),
    ("-3 dB (Hz)", "bandwidth_hz", "{:.3f}"),
    ("peak (dB)", "peak_db", "{:.2f}"),
    ("at (Hz)", "peak_hz", "{:.3f}"),
    ("GM (dB)", "gain_margin_db", "{:.2f}"),
    ("PM (deg)", "phase_margin_deg", "{:.1f}"),
    ("largest stable gain", "stable_gain", "{:.4g}"),
)

MARGINS = ("gain_margin_db", "phase_margin_deg")
"""The columns that a loop without margins shows as n/a."""


def _columns(rows):
    """TABLE_COLUMNS, without stable_gain unless a row has one."""
    if any(not np.isnan(row.stable_gain) for row in rows):
        return TABLE_COLUMNS
    return tuple(c for c in TABLE_COLUMNS if c[1] != "stable_gain")


def _csv_keys(rows):
    """summary.csv's columns: the table's, and margins_unavailable if a
    row has a reason."""
    keys = [key for _, key, _ in _columns(rows)]
    if any(row.margins_unavailable for row in rows):
        keys.append("margins_unavailable")
    return keys


def _row_cell(row, key, fmt):
    if key in MARGINS and row.margins_unavailable:
        return "n/a"
    return _cell(fmt, getattr(row, key))


def _cell(fmt, value):
    if isinstance(value, float) and np.isnan(value):
        return "-"
    if isinstance(value, float) and np.isinf(value):
        return "inf" if value > 0 else "-inf"
    return fmt.format(value)


def format_table(rows):
    """The summaries as a text table, one row each, columns aligned."""
    columns = _columns(rows)
    cells = [[title for title, _, _ in columns]]
    cells += [[_row_cell(row, key, fmt) for _, key, fmt in columns]
              for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(cells[0]))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                       for i, (c, w) in enumerate(zip(r, widths, strict=True)))
             for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def write_summary_csv(rows, path):
    """Writes the summaries as CSV (header: the fields) and returns the
    path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = _csv_keys(rows)
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(keys)
        for row in rows:
            writer.writerow([getattr(row, key) for key in keys])
    return path
