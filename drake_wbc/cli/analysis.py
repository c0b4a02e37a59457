"""The `drake-wbc bode` and `drake-wbc diagram` subcommands.

Each is a pair for drake_wbc.cli.main's SUBCOMMANDS: a function that adds its
arguments to an argparse parser and one that runs it and returns the exit
code. Heavy imports (Drake, matplotlib) happen inside the runners.
"""

import shutil
import subprocess
import sys
from pathlib import Path

from drake_wbc.cli.robot_option import add_robot_argument, on_robot

BODE_HELP = ("write the frequency responses of a scenario's filter chain "
             "and coupled DMPs: Bode plots (PNG), data (CSV) and a table of "
             "bandwidths, peaks and margins")
DIAGRAM_HELP = ("write the controller's and the station's Drake diagrams "
                "as Graphviz (.dot, and .svg where Graphviz's dot is "
                "installed)")
DOT_PROGRAM = "dot"
"""Graphviz's layout program, looked up on PATH."""


def _add_scenario_arguments(parser, command):
    parser.add_argument(
        "scenario", nargs="?", default=None,
        help="a scenario's name or YAML file (default: the default "
             "scenario)")
    parser.add_argument(
        "--output", type=Path, default=None,
        help=f"output folder (default: out/{command}/<scenario>)")
    add_robot_argument(parser, f"{command} of the scenario's controller")


def _scenario(args, command):
    """(name, Scenario, output folder) of the parsed `args`."""
    from drake_wbc.experiments.scenario import (
        DEFAULT_SCENARIO,
        find_scenario,
        load_scenario,
    )

    path = find_scenario(DEFAULT_SCENARIO if args.scenario is None
                         else args.scenario)
    output = args.output or Path("out") / command / path.stem
    return path.stem, on_robot(load_scenario(path), args), Path(output)


def add_bode_arguments(parser):
    """Adds `drake-wbc bode`'s arguments to `parser`."""
    _add_scenario_arguments(parser, "bode")


def run_bode(args):
    """Runs `drake-wbc bode`: writes every response of the scenario
    (drake_wbc.analysis.report) and prints the table. Returns 0."""
    from drake_wbc.analysis.report import write_bode_report

    name, scenario, output = _scenario(args, "bode")
    print(f"drake-wbc bode {name}: writing to {output}/")

    def progress(text):
        print(f"drake-wbc bode {name}: {text}", file=sys.stderr, flush=True)

    report = write_bode_report(scenario, output, progress=progress)
    print(report.table)
    print()
    for line in report.notes:
        print(line)
    print(f"\n{len(report.paths)} files written to {output}/")
    return 0


def add_diagram_arguments(parser):
    """Adds `drake-wbc diagram`'s arguments to `parser`."""
    _add_scenario_arguments(parser, "diagram")


def render_svg(dot_path):
    """Renders `dot_path` to SVG next to it with Graphviz's dot, if dot is
    on PATH. Returns the SVG's path, or None where dot is not installed.

    Raises:
        RuntimeError: if dot is there but fails, with its message on one
            line.
    """
    program = shutil.which(DOT_PROGRAM)
    if program is None:
        return None
    svg = Path(dot_path).with_suffix(".svg")
    result = subprocess.run([program, "-Tsvg", str(dot_path), "-o", str(svg)],
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        said = "; ".join(line.strip() for line in result.stderr.splitlines()
                         if line.strip())
        raise RuntimeError(f"{DOT_PROGRAM} failed on {dot_path} (exit "
                           f"{result.returncode})" + (f": {said}" if said
                                                      else ""))
    return svg


def run_diagram(args):
    """Runs `drake-wbc diagram`: writes controller.dot and station.dot
    (Drake's GetGraphvizString) and their SVGs where Graphviz is
    installed. Returns 0, or 1 where dot fails (said in one line; the
    .dot files are kept)."""
    from drake_wbc.controller import build_controller
    from drake_wbc.experiments.scenario import (
        controller_arm,
        scenario_station,
    )

    name, scenario, output = _scenario(args, "diagram")
    print(f"drake-wbc diagram {name}: writing to {output}/")
    output.mkdir(parents=True, exist_ok=True)
    diagrams = (
        ("controller", build_controller(
            scenario.controller, controller_arm(scenario)).diagram),
        ("station", scenario_station(scenario).diagram),
    )
    dots = []
    for stem, diagram in diagrams:
        dots.append(output / f"{stem}.dot")
        dots[-1].write_text(diagram.GetGraphvizString())
        print(f"  {dots[-1]}")
    missing = False
    for dot in dots:
        try:
            svg = render_svg(dot)
        except RuntimeError as error:
            sys.stdout.flush()
            print(f"drake-wbc diagram {name}: {error}; the .dot files are "
                  f"kept in {output}/", file=sys.stderr)
            return 1
        if svg is None:
            missing = True
        else:
            print(f"  {svg}")
    if missing:
        print(f"Graphviz's `{DOT_PROGRAM}` program is not on PATH, so no "
              "SVG was written; render the .dot files with e.g. "
              f"`{DOT_PROGRAM} -Tsvg controller.dot -o controller.svg` "
              "where Graphviz is installed, or paste them into any "
              "Graphviz viewer.")
    return 0
