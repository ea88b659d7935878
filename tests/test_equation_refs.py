"""Equation references in the package, twin/, docs/ and README.md use one numbering: the paper's LaTeX label with
the number the paper prints, ``eq:label (N)`` (issue 22).

The printed numbers count the paper's ``equation`` environments in order, unlabelled ones included. When the
paper's source lies beside the checkout (``../shared/paper/big-cbf.tex`` from the repository root) the table is
recomputed from it and must equal the one written here; otherwise the table written here is used.

What fails: a label the paper does not have; ``eq:label (N)`` (also ``eq:label`` in backquotes or brackets before
the ``(N)``) whose N is not the label's printed number; ``Eq. (N)``, ``Eq. N``, ``Eqs. (N)-(M)``, ``Equation N``
without a label next to it, or next to a label of another number; ``unlabelled (N)`` where display N has a label.
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT.parent / "shared" / "paper" / "big-cbf.tex"

#: label -> the number the paper prints for it (big-cbf.tex, every numbered display counted in order)
PRINTED = {
    "eq:execution": 1, "eq:obs_prop": 2, "eq:cov_prop": 3, "eq:predicted_obstacles": 4, "eq:goal_region": 5,
    "eq:true_safety_requirement": 6, "eq:behavior_set": 7, "eq:online_behavior_command": 8, "eq:goal_basis": 9,
    "eq:behavior_subgoals": 10, "eq:behavior_feedback": 11, "eq:behavior_rollout": 12, "eq:behavior_terms": 13,
    "eq:behavior_cost": 14, "eq:relative_position_error": 15, "eq:relative_error_bound": 17,
    "eq:robust_distance_condition": 19, "eq:shared_barrier": 20, "eq:uncertainty_margin": 21,
    "eq:behavior_acceptance": 22, "eq:analytic_workload": 24, "eq:cbf_condition": 25, "eq:hard_cbf_qp": 26,
    "eq:sim_cbf_energy": 27,
}
#: the numbered displays without a label: the true relative position, the reverse triangle inequality, gamma
UNLABELLED = {16, 18, 23}
TOTAL = 27

LABEL = re.compile(r"eq:([A-Za-z_]+)")
#: what may stand between a label and its printed number: closing backquotes or a bracket, then blanks
NUMBER_AFTER_LABEL = re.compile(r"[`\]]*\s*\((\d+)\)")
#: an equation named by number: "Eq. (14)", "Eq. 14", "Eqs. (2)-(3)", "Eqs. 9, 10", "Equation 5", "Eq.~(5)"
EQ_NUMBER = re.compile(r"\b(?:Eqs?|Eqn|Equations?)\b\.?\s*~?\s*\(?\s*(\d+)")
UNLABELLED_REF = re.compile(r"\bunlabell?ed(?:\s+display|\s+equation)?\s+\((\d+)\)")


def paper_table(tex: str) -> tuple[dict[str, int], set[int], int]:
    """(label -> number, unlabelled numbers, count) from the paper's source: every ``equation`` environment in
    order (comments removed), numbered unless starred."""
    tex = re.sub(r"(?<!\\)%[^\n]*", "", tex)
    labels, unlabelled, n = {}, set(), 0
    for body in re.findall(r"\\begin\{equation\}(.*?)\\end\{equation\}", tex, re.S):
        n += 1
        found = re.findall(r"\\label\{(eq:[^}]*)\}", body)
        if found:
            labels[found[0]] = n
        else:
            unlabelled.add(n)
    return labels, unlabelled, n


def table() -> tuple[dict[str, int], set[int]]:
    if PAPER.is_file():
        labels, unlabelled, _ = paper_table(PAPER.read_text(encoding="utf-8"))
        return labels, unlabelled
    return PRINTED, UNLABELLED


def scanned_files() -> list[Path]:
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for pkg in ("bigcbf", "twin"):
        for path in sorted((ROOT / pkg).rglob("*")):
            if path.suffix in (".py", ".md", ".toml") and "__pycache__" not in path.parts:
                files.append(path)
    return files


def problems(text: str, labels: dict[str, int], unlabelled: set[int]) -> list[str]:
    """Every reference in ``text`` that breaks the numbering, as 'line N: what'."""
    out = []

    def line(pos: int) -> int:
        return text.count("\n", 0, pos) + 1

    label_spans = []
    for m in LABEL.finditer(text):
        label = "eq:" + m.group(1)
        label_spans.append((m.start(), m.end(), label))
        if label == "eq:label":                 # the format itself, as the docs describe it
            continue
        if label not in labels:
            out.append(f"line {line(m.start())}: {label} is not a label of the paper")
            continue
        num = NUMBER_AFTER_LABEL.match(text, m.end())
        if num and int(num.group(1)) != labels[label]:
            out.append(f"line {line(m.start())}: {label} ({num.group(1)}), the paper prints ({labels[label]})")
    for m in EQ_NUMBER.finditer(text):
        n = int(m.group(1))
        # a label right before ("eq:x, Eq. (N)") or right after ("Eq. (N) [eq:x]", "Eq. (N) (``eq:x``)")
        near = [lab for s, e, lab in label_spans
                if 0 <= m.start() - e <= 4 or 0 <= s - m.end() <= 6]
        if not near:
            out.append(f"line {line(m.start())}: {m.group(0)!r} without its label (write eq:label ({n}))")
        elif all(labels.get(lab) != n for lab in near):
            out.append(f"line {line(m.start())}: {m.group(0)!r} next to {near[0]}, which the paper prints as "
                       f"({labels.get(near[0])})")
    for m in UNLABELLED_REF.finditer(text):
        if int(m.group(1)) not in unlabelled:
            out.append(f"line {line(m.start())}: {m.group(0)!r}: display ({m.group(1)}) is not an unlabelled one")
    return out


def test_table_matches_the_papers_source():
    """The table written here is the paper's; recomputed from its source when that is beside the checkout."""
    if not PAPER.is_file():
        pytest.skip(f"{PAPER} not beside the checkout: the written table is used")
    labels, unlabelled, n = paper_table(PAPER.read_text(encoding="utf-8"))
    assert labels == PRINTED
    assert unlabelled == UNLABELLED
    assert n == TOTAL


def test_written_table_is_consistent():
    """27 displays, each number once: the labelled ones and the unlabelled ones together."""
    numbers = sorted([*PRINTED.values(), *UNLABELLED])
    assert numbers == list(range(1, TOTAL + 1))


@pytest.mark.parametrize("text, expected", [
    ("the D_i of eq:shared_barrier (20)", 0),
    ("the D_i of ``eq:shared_barrier`` (20) and [eq:uncertainty_margin] (21)", 0),
    ("gamma, the unlabelled display (23) before eq:analytic_workload (24)", 0),
    ("eq:execution (real and complex forms)", 0),
    ("the D_i of Eq. (14)", 1),                    # the old numbering, no label
    ("D_i (Eq. 14)", 1),
    ("Eqs. (2)-(3)", 1),
    ("Equation 5", 1),
    ("eq:shared_barrier (14)", 1),                 # label and number disagree
    ("`eq:uncertainty_margin` (15)", 1),
    ("Eq. (15) (``eq:uncertainty_margin``)", 1),
    ("Eq. (21) (``eq:uncertainty_margin``)", 0),
    ("eq:no_such_label", 1),
    ("the unlabelled display (20)", 1),
])
def test_scanner_finds_what_it_should(text, expected):
    """The scanner itself: the canonical forms pass, the old numbering and mismatches fail."""
    assert len(problems(text, PRINTED, UNLABELLED)) == expected, problems(text, PRINTED, UNLABELLED)


def test_equation_references_use_the_printed_numbers():
    labels, unlabelled = table()
    files = scanned_files()
    assert len(files) > 50                        # the package, twin/, docs/ and README.md were found
    bad = []
    for path in files:
        for p in problems(path.read_text(encoding="utf-8"), labels, unlabelled):
            bad.append(f"{path.relative_to(ROOT)} {p}")
    assert not bad, "\n".join(bad)
