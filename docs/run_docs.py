"""Every command block of the README and the docs, run as a user pastes them.

For each document of :data:`DOCUMENTS`, in a scratch folder of its own, the ``bash`` and ``python``
blocks run in order (with ``docs/docblocks.py``, as ``docs/step10.py`` runs tutorial step 10):
each command of a ``bash`` block through bash, each ``python`` block with ``exec``. Blocks without
a language are printed output, not commands. Annotations (HTML comments, not rendered) on the
line before a block say what else to do with it:

* ``<!-- docs-run: skip (REASON) -->``: the block is not run (it installs, needs cargo, a dask
  cluster or a scanner's DICOM, ...); the runner lists it with its reason;
* ``<!-- docs-run: file NAME -->``: the block (a scenario, ...) is written to NAME in the folder,
  as the text before it tells the user to.

A ``python`` block runs in a fresh namespace, as pasted into a new interpreter, unless its first
line is a comment starting ``# continues``: then it runs in the namespace of the document's
previous ``python`` block (the text says so where the reader sees it). Sections run elsewhere are
left out (:data:`ELSEWHERE`: tutorial step 10 is ``docs/step10.py``'s).

Before running, every command is checked: no placeholder (``…`` anywhere, ``...`` outside a
comment) and, in Python, no name that neither the block nor the blocks it continues define.

``--small`` makes the substitutions of :data:`SMALL` (each with its reason) in the commands
before running them: the same commands at a smaller size, for the test suite
(``python/tests/test_docs.py``).

usage: python docs/run_docs.py [--small] [--show] [--workdir DIR] [DOCUMENT ...]

--small    the substitutions of SMALL made (the test suite's size)
--show     print what each command printed (to compare with the numbers the text quotes)
--workdir  run in DIR (created; one subfolder per document; kept) instead of temporary folders
DOCUMENT   paths relative to the repository (default: all of DOCUMENTS)
"""

from __future__ import annotations

import argparse
import builtins
import contextlib
import io
import re
import symtable
import sys
import tempfile
import tokenize
from dataclasses import dataclass, field
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
if str(DOCS) not in sys.path:  # docs/ is no package: its shared module is imported from beside this file
    sys.path.insert(0, str(DOCS))

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

DOCUMENTS = (
    # The documents with command blocks, relative to the repository (docs/physics.md has none).
    "README.md",
    "docs/tutorial.md",
    "docs/estimation.md",
    "docs/diagnose.md",
    "docs/head.md",
    "docs/reference.md",
    "docs/validation.md",
)
ELSEWHERE = {
    # document: (heading of a section whose blocks another script runs, which one)
    "docs/tutorial.md": ("## 10. ", "docs/step10.py (python/tests/test_tutorial.py)"),
}
SHRINK_SCENARIO = (
    "sed 's/elements_per_side = 16/elements_per_side = 8/; s/pitch_mm = 2.5/pitch_mm = 5.0/; s/element_size_mm = "
    "2.3/element_size_mm = 4.6/'"
)
"""The default scenario with 256 elements of twice the pitch (the same aperture) instead of 1024."""
# a verb on the embedded default: none of --scenario on the command's first line
VERBS_ON_THE_DEFAULT = re.compile(r"^arfi (simulate|calibrate|estimate|field|diagnose)\b(?!.*--scenario)", re.M)
SMALL = (
    # (document, text in its commands or in the files its blocks write (a str, or a re.Pattern for
    # re.sub), replacement, times it occurs, why). The replacement keeps each command's verb,
    # inputs and options, and what it shows; only the size changes. A replacement None leaves out
    # the whole command that holds the text.
    (
        "README.md",
        "arfi validate --out validation",
        "arfi validate --case water --out validation",
        1,
        "one of the nine validation cases (about 30 s for all nine; python/tests/test_validate.py runs the suite)",
    ),
    (
        "docs/validation.md",
        "arfi validate --out validation",
        "arfi validate --case water --out validation",
        1,
        "as in the README",
    ),
    (
        "docs/tutorial.md",
        "arfi scenario --default > phantom.toml",
        f"arfi scenario --default | {SHRINK_SCENARIO} > phantom.toml && cp phantom.toml small.toml",
        1,
        "the default scenario with 256 elements instead of 1024 (a quarter of the element fields a per-element "
        "estimate marches): phantom.toml, and small.toml for the commands below",
    ),
    (
        "docs/tutorial.md",
        VERBS_ON_THE_DEFAULT,
        r"arfi \1 --scenario small.toml",
        18,
        "the verbs that use the embedded default use the 256-element one instead",
    ),
    (
        "docs/tutorial.md",
        "arfi.Simulation()",
        'arfi.Simulation(arfi.Scenario.load("small.toml"))',
        1,
        "the Python likewise",
    ),
    ("docs/tutorial.md", "--groups 1024", "--groups 256", 5, "per element: 256 elements"),
    (
        "docs/tutorial.md",
        "--json diagnosis.json",
        "--json diagnosis.json --effects amplitude,broadening",
        1,
        "only the two effects it names at full size (the whole library: 85 s on 2 loaded cores; "
        "python/tests/test_diagnose.py runs it)",
    ),
    (
        "docs/tutorial.md",
        "spacing_mm = 0.375",
        "spacing_mm = 0.75",
        1,
        "plate.toml's grid at λ/4 in water instead of λ/8 (the plate's field takes a quarter of the time)",
    ),
    (
        "docs/diagnose.md",
        ".diagnose(image)",
        '.diagnose(image, effects=["amplitude", "broadening"])',
        1,
        "two of the library's effects, the one it names among them (the whole library: 2 minutes on 2 loaded cores)",
    ),
    (
        "docs/tutorial.md",
        "--voxel-mm 1",
        "--voxel-mm 2",
        1,
        "the envelope's head CT in 2 mm voxels instead of 1 mm",
    ),
    (
        "docs/tutorial.md",
        "s/frequency_hz = 650000.0/frequency_hz = 220000.0/' env.toml",
        "s/frequency_hz = 650000.0/frequency_hz = 220000.0/; s/elements = 1024/elements = 256/' env.toml",
        1,
        "the envelope's hemisphere with 256 elements instead of 1024",
    ),
    (
        "docs/tutorial.md",
        "--spacing-mm 15",
        "--spacing-mm 30",
        1,
        "a box of 18 targets 30 mm apart instead of 100 targets 15 mm apart",
    ),
    (
        "docs/head.md",
        "arfi phantom --out",
        "arfi phantom --voxel-mm 2 --out",
        2,
        "the head CT in 2 mm voxels instead of 0.5 mm (as tutorial step 10 at its small size)",
    ),
    (
        "docs/head.md",
        "arfi field --scenario head_hemi.toml",
        None,
        1,
        "not run: the 1024-element hemisphere at 650 kHz marches a 540 x 540 x 256 grid (tutorial step 10 runs a "
        "hemisphere through a head at a small size: python/tests/test_tutorial.py)",
    ),
    (
        "docs/head.md",
        "arfi predict --scenario head_hemi.toml",
        None,
        1,
        "not run: as the hemisphere's field (80-330 s, 3.8 GiB)",
    ),
    (
        "docs/tutorial.md",
        "arfi sweep --noise-rad 0.01 0.02 0.05 --images 1 2 3 --methods lbfgs nelder-mead --seeds 5 --out sweep",
        None,
        1,
        "not run: 90 trials on a local dask cluster, 258 s on 2 loaded cores (python/tests/test_sweep.py runs sweeps)",
    ),
)
ANNOTATION = re.compile(r"^<!-- docs-run: (skip|file) (.*\S) -->$")
CONTINUES = re.compile(r"^# continues\b")


@dataclass
class Step:
    """One block of a document and what to do with it."""

    document: str
    line: int
    """The block's opening fence, 1-based."""
    action: str
    """``"run"``, ``"skip"`` or ``"file"``."""
    language: str
    commands: list[Command] = field(default_factory=list)
    note: str = ""
    """The skip's reason or the file's name."""
    continues: bool = False
    """A ``python`` block that runs in the previous one's namespace."""
    text: str = ""
    """The block's text (what a ``file`` step writes)."""

    def where(self) -> str:
        return f"{self.document}:{self.line}"


@dataclass
class Outcome:
    """A run step's commands as run (after the substitutions), and what each printed, or the error."""

    step: Step
    codes: list[str | None]
    """None: a command left out at the small size (:data:`SMALL`)."""
    runs: list[Run]
    error: str | None = None


def steps(document: str) -> list[Step]:
    """The code blocks of ``document`` (relative to the repository) in order, with their actions."""
    lines = (ROOT / document).read_text().splitlines()
    end = len(lines)
    if document in ELSEWHERE:
        heading = ELSEWHERE[document][0]
        start = next((i for i, line in enumerate(lines) if line.startswith(heading)), None)
        if start is None:
            raise CommandError(f"{document}: no heading starting {heading!r} (ELSEWHERE in docs/run_docs.py)")
        after = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        lines = lines[:start] + [""] * (after - start) + lines[after:]  # keeps the line numbers
    out = []
    for block in fenced_blocks(lines, 0, end, document):
        before = next((lines[i].strip() for i in range(block.open - 1, -1, -1) if lines[i].strip()), "")
        annotation = ANNOTATION.match(before)
        text = "\n".join(lines[block.open + 1 : block.close])
        step = Step(document, block.open + 1, "run", block.language, text=text)
        if annotation:
            step.action, step.note = annotation.groups()
        elif block.language not in ("bash", "python"):
            continue  # output, or a fragment of a file the text shows
        if step.action == "skip" and not (step.note.startswith("(") and step.note.endswith(")")):
            raise CommandError(f"{step.where()}: a skip without its reason in parentheses: {before}")
        step.commands = block_commands(lines, block, document)
        step.continues = block.language == "python" and bool(CONTINUES.match(text.lstrip()))
        out.append(step)
    return out


def without_comments(command: Command) -> str:
    """The command's code without its comments (Python's by its tokens; bash's from a ``#`` that
    starts a word)."""
    if command.kind == "python":
        try:
            tokens = tokenize.generate_tokens(io.StringIO(command.code).readline)
            return tokenize.untokenize((t.type, t.string) for t in tokens if t.type != tokenize.COMMENT)
        except (tokenize.TokenError, SyntaxError):
            return command.code
    return "\n".join(re.sub(r"(^|\s)#.*$", "", line) for line in command.code.splitlines())


def placeholders(step: Step) -> list[str]:
    """Where a command of ``step`` holds a placeholder: ``…`` anywhere, ``...`` outside a comment."""
    bad = []
    for command in step.commands:
        shown = "\n".join([command.code] + command.output)
        code = without_comments(command)
        for mark, text in (("…", shown), ("...", code)):
            if mark in text:
                bad.append(f"{step.where()}: `{command.code.splitlines()[0]}` holds the placeholder {mark!r}")
    return bad


def names(code: str) -> tuple[set[str], set[str]]:
    """The global names the Python ``code`` defines at its top level, and those it uses."""
    top = symtable.symtable(code, "block", "exec")
    defined = {s.get_name() for s in top.get_symbols() if s.is_assigned() or s.is_imported()}
    used: set[str] = set()

    def walk(table: symtable.SymbolTable) -> None:
        for s in table.get_symbols():
            if s.is_referenced() and (table is top or s.is_global()):
                used.add(s.get_name())
        for child in table.get_children():
            walk(child)

    walk(top)
    return defined, used


def undefined(document_steps: list[Step]) -> list[str]:
    """Each name a ``python`` block uses that neither it, nor the blocks it continues, nor Python defines."""
    bad, known = [], set(dir(builtins))
    defined: set[str] = set()
    for step in document_steps:
        if step.action != "run" or step.language != "python":
            continue
        if not step.continues:
            defined = set()
        try:
            mine, used = names(step.commands[0].code)
        except SyntaxError as e:
            bad.append(f"{step.where()}: not Python: {e}")
            continue
        missing = sorted(used - mine - defined - known)
        if missing:
            bad.append(
                f"{step.where()}: uses {', '.join(missing)}, defined by no earlier block it continues (define it, or "
                "start the block with '# continues ...')"
            )
        defined |= mine
    return bad


def problems(document: str) -> list[str]:
    """What is wrong with ``document``'s commands before running them."""
    document_steps = steps(document)
    return [p for s in document_steps if s.action == "run" for p in placeholders(s)] + undefined(document_steps)


def substitutions(document: str) -> list[tuple[str, str, int, str]]:
    """:data:`SMALL`'s rows for ``document``: (text, replacement, times, why)."""
    return [(old, new, times, why) for doc, old, new, times, why in SMALL if doc == document]


def texts(document_steps: list[Step]) -> dict[tuple[int, int], str]:
    """The commands by (step, command) index, and each file a step writes by (step, -1)."""
    codes = {
        (i, j): c.code for i, s in enumerate(document_steps) if s.action == "run" for j, c in enumerate(s.commands)
    }
    return codes | {(i, -1): s.text for i, s in enumerate(document_steps) if s.action == "file"}


def shrink(document: str, document_steps: list[Step]) -> dict[tuple[int, int], str | None]:
    """:func:`texts` at the small size: each substitution of :data:`SMALL` made where it occurs,
    the number of times it says (None: a command left out)."""
    codes: dict[tuple[int, int], str | None] = dict(texts(document_steps))
    for old, new, times, _ in substitutions(document):
        if isinstance(old, re.Pattern):
            done = {k: (None, 0) if code is None else old.subn(new, code) for k, code in codes.items()}
            found, codes = sum(n for _, n in done.values()), {k: code for k, (code, _) in done.items()}
        else:
            found = sum(code.count(old) for code in codes.values() if code is not None)
            codes = {
                k: code if code is None or old not in code else None if new is None else code.replace(old, new)
                for k, code in codes.items()
            }
        if found != times:
            shown = old.pattern if isinstance(old, re.Pattern) else old
            raise CommandError(
                f"{document}: its commands hold {shown!r} {found} times, not {times}: update SMALL in docs/run_docs.py"
            )
    return codes


def run_document(document: str, folder: Path, small: bool, log=print) -> list[Outcome]:
    """Runs ``document``'s blocks in ``folder`` (at the small size if ``small``) until one fails;
    an outcome per step that runs or writes a file."""
    document_steps = steps(document)
    codes = shrink(document, document_steps) if small else texts(document_steps)
    outcomes, namespace = [], None
    for i, step in enumerate(document_steps):
        if step.action == "skip":
            log(f"run_docs: {step.where()}: skipped {step.note}")
            continue
        if step.action == "file":
            (folder / step.note).write_text(codes[(i, -1)] + "\n")
            log(f"run_docs: {step.where()}: wrote {step.note}")
            continue
        if step.language == "python" and not (step.continues and namespace is not None):
            namespace = {"__name__": "__docs__"}
        outcome = Outcome(step, [codes[(i, j)] for j in range(len(step.commands))], [])
        outcomes.append(outcome)
        for command, code in zip(step.commands, outcome.codes):
            if code is None:
                log(f"run_docs: {step.where()}: left out at the small size: {command.code.splitlines()[0][:80]}")
                continue
            try:
                outcome.runs.append(run_command(command.kind, code, folder, namespace))
            except CommandError as e:
                outcome.error = f"{step.where()}: {e}"
            except Exception as e:  # a python block's exception, as the interpreter would show it
                outcome.error = f"{step.where()}: `{code.splitlines()[0]}` raised {type(e).__name__}: {e}"
            if outcome.error:
                log(f"run_docs: {outcome.error}")
                return outcomes
            log(f"run_docs: {outcome.runs[-1].seconds:6.1f} s  {step.where()}  {code.splitlines()[0][:90]}")
    return outcomes


def arguments(argv: list[str]) -> argparse.Namespace:
    """The command line (see the module's docstring)."""
    p = Parser(prog="run_docs.py", description="Runs every command block of the README and the docs.")
    p.add_argument("--small", action="store_true", help="the substitutions of SMALL made")
    p.add_argument("--show", action="store_true", help="print what each command printed")
    p.add_argument("--workdir", metavar="DIR", help="run in DIR (created, kept) instead of temporary folders")
    p.add_argument("documents", nargs="*", metavar="DOCUMENT", help="default: all")
    args = p.parse_args(argv)
    for d in args.documents:
        if d not in DOCUMENTS:
            raise UsageError(f"run_docs.py: {d}: not one of {', '.join(DOCUMENTS)}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Checks and runs the documents' commands; exit 1 if one fails."""
    return exit_status("run_docs.py", lambda: run_main(arguments(sys.argv[1:] if argv is None else argv)))


def run_main(args: argparse.Namespace) -> int:
    """:func:`main`'s work."""
    failed = []
    for document in args.documents or DOCUMENTS:
        bad = problems(document)
        for line in bad:
            print(f"run_docs: {line}")
        with contextlib.ExitStack() as stack:
            if args.workdir:
                folder = Path(args.workdir).resolve() / document.replace("/", "_")
                folder.mkdir(parents=True, exist_ok=True)
            else:
                folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="run_docs-")))
            outcomes = run_document(document, folder, args.small)
        if args.show:
            for outcome in outcomes:
                for code, run in zip([c for c in outcome.codes if c is not None], outcome.runs):
                    print("\n".join([f"$ {code}"] + [f"# {line}".rstrip() for line in run.printed]))
        if bad or any(o.error for o in outcomes):
            failed.append(document)
    print(f"run_docs: failed: {', '.join(failed)}" if failed else "run_docs: every block ran")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
