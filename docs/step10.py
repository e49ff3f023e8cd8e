"""Tutorial step 10 ("From a head CT to a corrected focus"), run: what it shows is what the code prints.

Reads step 10 of ``docs/tutorial.md`` (the single source of its commands), runs its commands in
order in a scratch folder as a user would (each command of the ``bash`` blocks through bash with
this interpreter's ``arfi`` first on the PATH, the ``python`` block with ``exec``), and writes back
into the tutorial

* after each command, its printed lines as ``# ...`` lines (replacing those there), and after each
  command that took a second or more its wall-clock time (``# 12 s``);
* the rows of the table "drive through the patient's skull": the focal |p| at the target through
  the patient's skull (``arfi.analysis.prediction.predict`` of ``patient.toml``: its ``skull_responses``)
  for the clinic's drive, the prediction's reference steering minus no phases, ``prior.npy``,
  ``estimate.npy`` and ``truth.npy`` (shifted from the patient's own reference steering to the
  clinic's), and ``truth.optimal_pa``;
* the figures the step embeds (``![..](figures/X.png)``), each copied from the file named in
  backquotes last before it (e.g. ``predict/predict_section.png``).

usage: python docs/step10.py [--small] [--check] [--workdir DIR]

--small    the same commands at a small size (a 2 mm CT, 220 kHz instead of 650 kHz), faster
           and in less memory than the full step (about 5 minutes, 7.3 GB at most); prints the
           step as it would write it and writes nothing
--check    writes nothing; exit 1 if the tutorial differs from what the commands print (times
           aside), or with --small if a printed line differs in form (numbers aside)
--workdir  run in DIR (created; kept afterwards) instead of a temporary folder
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import re
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

DOCS = Path(__file__).resolve().parent
if str(DOCS) not in sys.path:  # docs/ is no package: its shared module is imported from beside this file
    sys.path.insert(0, str(DOCS))

from docblocks import TIME as TIME  # noqa: E402 (read through this module by python/tests/test_tutorial.py)
from docblocks import (  # noqa: E402 (after the path is set)
    Command,
    CommandError,
    Parser,
    Run,
    UsageError,
    block_commands,
    exit_status,
    fenced_blocks,
    run_command,
)
from docblocks import is_output as is_output  # noqa: E402 (read through this module by python/tests/test_tutorial.py)

TUTORIAL = DOCS / "tutorial.md"
HEADING = "## 10. "
TABLE_HEADER = "| drive through the patient's skull |"

SMALL = (
    # (text in the tutorial's commands, its replacement at the small size); each must occur once.
    ("arfi phantom --out", "arfi phantom --voxel-mm 2 --out"),
    ("s/elements = 1024/", "s/frequency_hz = 650000.0/frequency_hz = 220000.0/; s/elements = 1024/"),
)
TABLE_ROWS = (
    # (row label, the phases subtracted from the reference steering: None for none, "optimal" for the bound)
    ("uncorrected (reference steering)", None),
    ("the CT prediction subtracted (`prior.npy`)", "prior.npy"),
    ("what `arfi estimate` recommends subtracted (`estimate.npy`)", "estimate.npy"),
    ("the real skull's own prediction subtracted (`truth.npy`)", "truth.npy"),
    ("`optimal` of `truth.json` (every wave in phase at the target)", "optimal"),
)
TIMED_S = 1.0  # commands faster than this get no time after them
NUMBER = re.compile(r"[-+]?(?:\d+(?:\.\d+)?|\.\d+)(?:e[-+]?\d+)?")
SECONDS = re.compile(r"\b\d+(?:\.\d+)? s\b")
RECOMMENDED = re.compile(r"recommended: \w+")


StepError = CommandError  # the tutorial or a command failed: reported as one line, exit 1


@dataclass
class StepRun:
    """Step 10 run: its commands as written, what each printed, and the table."""

    commands: list[Command]
    runs: list[Run]
    table: list[tuple[str, float, float]]
    """Per row of :data:`TABLE_ROWS`: label, focal |p| (Pa), fraction of ``optimal``."""


def section(lines: list[str]) -> tuple[int, int]:
    """Indices of step 10's first line and of the next step's heading."""
    starts = [i for i, line in enumerate(lines) if line.startswith(HEADING)]
    if len(starts) != 1:
        raise StepError(f"{TUTORIAL}: expected one heading starting {HEADING!r}, found {len(starts)}")
    end = next((i for i in range(starts[0] + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    return starts[0], end


def parse(lines: list[str]) -> list[Command]:
    """Step 10's commands in order: every command of its ``bash`` blocks and its ``python`` blocks."""
    start, end = section(lines)
    commands = [
        c
        for block in fenced_blocks(lines, start, end, str(TUTORIAL))
        for c in block_commands(lines, block, str(TUTORIAL))
    ]
    if not commands:
        raise StepError(f"{TUTORIAL}: step 10 has no commands")
    return commands


def shrink(codes: list[str]) -> list[str]:
    """The commands at the small size: each of :data:`SMALL`'s replacements made where it occurs once."""
    codes = list(codes)
    for old, new in SMALL:
        where = [k for k, code in enumerate(codes) if old in code]
        if len(where) != 1 or codes[where[0]].count(old) != 1:
            raise StepError(
                f"{TUTORIAL}: step 10's commands hold {old!r} {sum(c.count(old) for c in codes)} times, not once: "
                "update SMALL in docs/step10.py"
            )
        codes[where[0]] = codes[where[0]].replace(old, new)
    return codes


def focal_table(folder: Path) -> list[tuple[str, float, float]]:
    """:data:`TABLE_ROWS` measured at the target through the patient's skull (``patient.toml``)."""
    import json

    import numpy as np

    from arfi.analysis.prediction import predict
    from arfi.scenario import Scenario

    truth = predict(Scenario.load(folder / "patient.toml"))
    # The clinic drives the prediction's reference steering (the CT where it is registered) minus
    # the phases; the patient's own prediction is relative to its own reference steering.
    clinic = np.asarray(json.loads((folder / "prediction.json").read_text())["reference_steering_rad"])
    rows = []
    for label, phases in TABLE_ROWS:
        if phases == "optimal":
            pa = truth.optimal_pa
        else:
            subtracted = np.zeros(clinic.size) if phases is None else np.load(folder / phases)
            if phases == "truth.npy":
                subtracted = subtracted + clinic - truth.reference_steering_rad
            pa = float(np.abs(np.sum(truth.skull_responses * np.exp(1j * (clinic - subtracted)))))
        rows.append((label, pa, pa / truth.optimal_pa))
    return rows


def run_step(folder: Path, small: bool, log=print) -> StepRun:
    """Runs step 10's commands (at the small size if ``small``) in ``folder``, then the table."""
    commands = parse(TUTORIAL.read_text().splitlines())
    codes = [c.code for c in commands]
    runs = []
    for command, code in zip(commands, shrink(codes) if small else codes):
        runs.append(run_command(command.kind, code, folder))
        log(f"step10: {runs[-1].seconds:6.1f} s  {code.splitlines()[0][:100]}")
    return StepRun(commands, runs, focal_table(folder))


def table_lines(table: list[tuple[str, float, float]]) -> list[str]:
    """The table's rows as markdown."""
    return [f"| {label} | {pa / 1e6:.3f} | {fraction:.3f} |" for label, pa, fraction in table]


def table_rows_at(lines: list[str]) -> tuple[int, int]:
    """Indices of the first row of step 10's table (after its header and rule) and past its last."""
    start, end = section(lines)
    header = next((i for i in range(start, end) if lines[i].startswith(TABLE_HEADER)), None)
    if header is None:
        raise StepError(f"{TUTORIAL}: step 10 has no table starting {TABLE_HEADER!r}")
    stop = header + 2
    while stop < end and lines[stop].startswith("|"):
        stop += 1
    return header + 2, stop


def render(lines: list[str], step: StepRun) -> list[str]:
    """The tutorial's lines with the printed lines, times and table of ``step`` (the tutorial's
    own commands, whatever size ran)."""
    edits = [table_rows_at(lines) + (table_lines(step.table),)]
    for command, run in zip(step.commands, step.runs):
        code = command.code.splitlines()
        if command.kind == "bash" and run.seconds >= TIMED_S:
            code[-1] += f"   # {run.seconds:.0f} s"
        end = command.last + 1 + len(command.output)
        edits.append((command.first, end, code + [f"# {line}".rstrip() for line in run.printed]))
    new = list(lines)
    for begin, end, replacement in sorted(edits, reverse=True):
        new[begin:end] = replacement
    return new


def figures(lines: list[str]) -> list[tuple[str, str]]:
    """Step 10's embedded figures: (the file a command writes, named in backquotes last before the
    embed; the embed's path relative to docs/)."""
    start, end = section(lines)
    pairs, named = [], None
    for line in lines[start:end]:
        for match in re.finditer(r"`([^`\s]+\.png)`|!\[[^\]]*\]\(([^)\s]+\.png)\)", line):
            if match.group(1):
                named = match.group(1)
            elif named is None:
                raise StepError(f"{TUTORIAL}: figure {match.group(2)} follows no `file.png` a command writes")
            else:
                pairs.append((named, match.group(2)))
    return pairs


def form(line: str) -> str:
    """A printed line with its numbers replaced by ``#``, and the phases an estimate recommends by
    ``#`` (the size decides whether the images can judge the prediction): what must not change
    with the size."""
    return RECOMMENDED.sub("recommended: #", NUMBER.sub("#", line))


#: Lines a command prints only in some cases (an estimate's warnings, a hotter place than the
#: focus): the size may change whether they appear, so the form comparison leaves them out.
CONDITIONAL = re.compile(
    r"^(estimate: (AMBIGUOUS|MODEL MISMATCH|KEPT THE PREDICTION|next acquisition|PRIOR NOT MOVED|prior moved"
    r"|NOT CONVERGED|NOT SUPPORTED)"
    r"|field: hottest)"
)


def form_mismatches(step: StepRun) -> list[str]:
    """Each command whose printed lines differ in form from the tutorial's ``# ...`` lines (the
    :data:`CONDITIONAL` ones aside)."""
    bad = []
    for command, run in zip(step.commands, step.runs):
        shown, printed = (
            [form(x) for x in lines if not CONDITIONAL.match(x)] for lines in (command.output, run.printed)
        )
        if shown != printed:
            bad.append(
                f"`{command.code.splitlines()[0]}`:\n  tutorial: "
                + "\n            ".join(shown)
                + "\n  printed:  "
                + "\n            ".join(printed)
            )
    return bad


def untimed(text: str) -> str:
    """``text`` with every duration (``12 s``, ``62.3 s``) made ``# s``: what --check ignores."""
    return SECONDS.sub("# s", text)


def stale_figures(lines: list[str], folder: Path) -> list[str]:
    """The embedded figures whose file differs from what the commands wrote."""
    return [
        target
        for source, target in figures(lines)
        if not (DOCS / target).exists() or (DOCS / target).read_bytes() != (folder / source).read_bytes()
    ]


def write(lines: list[str], new: list[str], folder: Path) -> None:
    """Writes the tutorial and copies the figures."""
    TUTORIAL.write_text("\n".join(new) + "\n")
    for source, target in figures(lines):
        shutil.copyfile(folder / source, DOCS / target)
        print(f"step10: {source} -> docs/{target}")
    print(f"step10: wrote {TUTORIAL}")


def check(lines: list[str], new: list[str], step: StepRun, folder: Path, small: bool) -> int:
    """Exit status of --check: 0 if the tutorial shows what the commands print."""
    if small:
        bad = form_mismatches(step)
        print("\n".join(bad) if bad else "step10: every printed line has the tutorial's form")
        return 1 if bad else 0
    old, now = untimed("\n".join(lines)).splitlines(), untimed("\n".join(new)).splitlines()
    diff = list(difflib.unified_diff(old, now, "tutorial.md", "printed", lineterm=""))
    stale = stale_figures(lines, folder)
    print(
        "\n".join(diff + [f"step10: docs/{t} differs from what the commands draw" for t in stale])
        or "step10: the tutorial shows what the commands print"
    )
    return 1 if diff or stale else 0


def arguments(argv: list[str]) -> argparse.Namespace:
    """The command line (see the module's docstring)."""
    p = Parser(prog="step10.py", description="Runs tutorial step 10 and writes what its commands print into it.")
    p.add_argument("--small", action="store_true", help="a 2 mm CT at 220 kHz; prints instead of writing")
    p.add_argument("--check", action="store_true", help="writes nothing; exit 1 if the tutorial differs")
    p.add_argument("--workdir", metavar="DIR", help="run in DIR (created, kept) instead of a temporary folder")
    args = p.parse_args(argv)
    if args.workdir and Path(args.workdir).exists() and any(Path(args.workdir).iterdir()):
        raise UsageError(f"step10.py: --workdir {args.workdir}: must be new or empty")
    return args


def main(argv: list[str] | None = None) -> int:
    """Runs step 10 and writes, prints or checks what it printed; the exit status."""
    return exit_status("step10.py", lambda: run_main(arguments(sys.argv[1:] if argv is None else argv)))


def run_main(args: argparse.Namespace) -> int:
    """:func:`main`'s work."""
    lines = TUTORIAL.read_text().splitlines()
    with contextlib.ExitStack() as stack:
        if args.workdir:
            folder = Path(args.workdir).resolve()
            folder.mkdir(parents=True, exist_ok=True)
        else:
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="step10-")))
        step = run_step(folder, args.small)
        new = render(lines, step)
        if args.check:
            return check(lines, new, step, folder, args.small)
        if args.small:
            start, end = section(new)
            print("\n".join(new[start:end]))
            print("\n".join(f"step10: would copy {s} -> docs/{t}" for s, t in figures(lines)))
            return 0
        write(lines, new, folder)
        return 0


if __name__ == "__main__":
    sys.exit(main())
