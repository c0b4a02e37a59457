"""Every reference to the paper in the project's text names a section
and an equation that the paper has, by its label where it has one.

The docstrings cite the paper's equations by label (eq. (wb_error)) and
the unlabelled ones by number (eq. (2)); a number that the paper's
equation also has a label for, or a section that is not the paper's,
sends a reader to the wrong place. The paper's structure is written out
here from its text (shared/paper): its sections, its labels in order and
the numbers of its unlabelled equations.
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SECTIONS = {
    "I", "II",
    "III", "III-A", "III-B", "III-C",
    "IV", "IV-A", "IV-B", "IV-C",
    "V", "V-A", "V-B", "V-C", "V-D", "V-E",
    "VI",
}
"""I Introduction, II Related work, III Preliminaries (A kinematic
modelling, B weighted distribution, C coupling DMPs), IV Methodology (A
robust coordination, B compliant control via CDMPs, C intuitive pHRI), V
Experiments (A set-up, B trajectory tracking, C robust whole-body
control, D wiping, E pHRI), VI Conclusion."""

NUMBERED = {
    1: "fk", 2: None, 3: None, 4: "wln", 5: "wbsln", 6: None, 7: None,
    8: None, 9: "stiff-dmp", 10: "lp-admit", 11: "admit-ctrl",
    12: "admit-dmp", 13: "tf-admit", 14: "weight-factors", 15: None,
    16: None, 17: None, 18: "wbccm", 19: "filtering", 20: None, 21: None,
    22: "wb_error", 23: "compensation", 24: "transition", 25: "deviation",
    26: "cdmp-wb", 27: "cdmp-base", 28: None, 29: "cdmp-arm",
    30: "cdmp-wb-error", 31: None, 32: None,
}
"""The paper's equations in order, each with its label (None: it has
none, and is cited by its number)."""

OWN_LABELS = {"base_lag", "allowed", "approach", "protective"}
"""Labels of equations that are the project's, not the paper's (each
module that defines one says so)."""

_CITATION = re.compile(
    r"\beqs?\.\s+((?:\([\w:-]+\)(?:\s*(?:,\s*and|,|/|-|and)\s*)?)+)")
_SECTION = re.compile(r"\bSec\.\s+([IVX]+(?:-[A-Z])?)\b")


def _texts():
    """(path, text) of the package, the tests, the examples, the tools,
    the scenarios and the README."""
    patterns = ("drake_wbc/**/*.py", "tests/**/*.py", "examples/**/*.py",
                "tools/**/*.py", "diagrams/**/*.yaml", "README.md")
    for pattern in patterns:
        for path in sorted(ROOT.glob(pattern)):
            if path != Path(__file__).resolve():
                yield path.relative_to(ROOT), path.read_text()


def _line(text, index):
    return text.count("\n", 0, index) + 1


def test_every_cited_equation_is_the_papers_by_its_label():
    labels = {label for label in NUMBERED.values() if label}
    unlabelled = {str(n) for n, label in NUMBERED.items() if label is None}
    wrong = []
    for path, text in _texts():
        for match in _CITATION.finditer(text):
            for token in re.findall(r"\(([\w:-]+)\)", match.group(1)):
                if token in labels or token in unlabelled or (
                        token in OWN_LABELS):
                    continue
                hint = (f" (the paper's eq. ({NUMBERED[int(token)]}))"
                        if token.isdigit() and int(token) in NUMBERED
                        else "")
                wrong.append(f"{path}:{_line(text, match.start())}: "
                             f"eq. ({token}){hint}")
    assert not wrong, "\n".join(wrong)


def test_every_cited_section_is_the_papers():
    wrong = [f"{path}:{_line(text, match.start())}: Sec. {match.group(1)}"
             for path, text in _texts()
             for match in _SECTION.finditer(text)
             if match.group(1) not in SECTIONS]
    assert not wrong, "\n".join(wrong)
