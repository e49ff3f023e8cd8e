"""The docs run as written: every ``bash`` and ``python`` block of the README and the docs, as
``docs/run_docs.py --small`` runs them (in order per document, in a temporary folder, through bash
and ``exec`` as a user pastes them, with the substitutions of its SMALL table).

What is checked: no command holds a placeholder (``…``, or ``...`` outside a comment); no Python
block uses a name that neither it nor the blocks it says it continues define; every block that
is not skipped by a visible annotation runs (exit 0, no exception). Tutorial step 10 is left to
``test_tutorial.py``.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "docs"))  # docs/ is no package
import run_docs  # noqa: E402


@pytest.mark.parametrize("document", run_docs.DOCUMENTS)
def test_commands_hold_no_placeholder_and_use_only_defined_names(document):
    assert run_docs.problems(document) == []


@pytest.mark.parametrize("document", run_docs.DOCUMENTS)
def test_every_block_runs(document, tmp_path):
    outcomes = run_docs.run_document(document, tmp_path, small=True, log=lambda line: None)
    assert [o.error for o in outcomes if o.error] == []
    assert all(len(o.runs) == sum(code is not None for code in o.codes) for o in outcomes)


def test_skips_say_why_and_step_10_is_left_to_test_tutorial():
    steps = [s for d in run_docs.DOCUMENTS for s in run_docs.steps(d)]
    assert all(s.note.startswith("(") for s in steps if s.action == "skip")
    lines = (run_docs.ROOT / "docs" / "tutorial.md").read_text().splitlines()
    step10 = next(i for i, line in enumerate(lines) if line.startswith("## 10. ")) + 1
    after = next(i for i in range(step10, len(lines)) if lines[i].startswith("## ")) + 1
    assert not [s.where() for s in steps if s.document == "docs/tutorial.md" and step10 <= s.line <= after]


def test_a_python_block_that_does_not_say_it_continues_starts_afresh(tmp_path):
    # The name check follows the run: only a block starting '# continues' sees the names before it.
    (tmp_path / "doc.md").write_text(
        "```python\nx = 1\n```\n\n```python\n# continues the block above\nprint(x)\n```\n\n```python\nprint(x)\n```\n"
    )
    steps = run_docs.steps(str(tmp_path / "doc.md"))
    assert [s.continues for s in steps] == [False, True, False]
    assert run_docs.undefined(steps) == [
        f"{steps[2].where()}: uses x, defined by no earlier block it continues (define it, or start the block with '# "
        "continues ...')"
    ]
    outcomes = run_docs.run_document(str(tmp_path / "doc.md"), tmp_path, small=False, log=lambda line: None)
    assert [o.runs[0].printed if o.runs else None for o in outcomes] == [[], ["1"], None]
    assert "NameError" in outcomes[2].error


def test_a_placeholder_in_a_command_is_found(tmp_path):
    (tmp_path / "doc.md").write_text("```bash\narfi sweep ... --out s   # ok...\n# sweep: printed...\n```\n")
    steps = run_docs.steps(str(tmp_path / "doc.md"))
    assert len(run_docs.placeholders(steps[0])) == 1


def test_the_readme_shows_what_the_main_job_prints(tmp_path, capsys):
    """The README's block of the main job's output is what the job prints (its seeds are fixed),
    the time apart."""
    from arfi.cli import main

    text = (run_docs.ROOT / "README.md").read_text()
    block = text[text.index("What the main job prints") :].split("```")[1]
    shown = [line for line in block.splitlines() if line.startswith("reproduce:")]
    assert len(shown) == 3, block
    assert main(["reproduce", "--case", "16", "--repeats", "3", "--out", str(tmp_path / "results")]) == 0
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("reproduce:")]

    def untimed(lines):
        return [re.sub(r" in [0-9.]+ s -> \S+$", " in T s", line) for line in lines]

    assert untimed(printed) == untimed(shown)
