"""The commands of the docs' code blocks, read and run as a user pastes them.

Shared by ``docs/step10.py`` (tutorial step 10, whose printed lines it writes back) and
``docs/run_docs.py`` (every command block of the README and the docs). A ``bash`` block holds
commands, each followed by the lines it prints as ``# ...`` lines (a command continues over lines
ending in a backslash); a ``python`` block is one command, its printed lines (``# ...``) last.
Bash commands run through bash with this interpreter's ``arfi`` first on the PATH; Python ones
with ``exec`` in the folder, in a fresh namespace or one given.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

TIME = re.compile(r"\s+# \d+ s$")  # a command line's trailing time (``# 12 s``)
FENCE = re.compile(r"^```(\S*)\s*$")


class CommandError(Exception):
    """A document that cannot be read as commands, or a command that failed: one line."""


class UsageError(Exception):
    """Bad command-line input of a docs script: reported as one line, exit 2."""


class Parser(argparse.ArgumentParser):
    """Reports a usage error as one line starting with the script's name (argparse prints the usage too)."""

    def error(self, message: str) -> None:
        raise UsageError(f"{self.prog}: {message}")


def exit_status(name: str, work) -> int:
    """Runs ``work()``, a script's work returning its exit status: a :class:`UsageError` is one line
    on stderr and exit 2, a :class:`CommandError` one line starting with ``name`` and exit 1."""
    try:
        return work()
    except UsageError as e:
        print(e, file=sys.stderr)
        return 2
    except CommandError as e:
        print(f"{name}: {e}", file=sys.stderr)
        return 1


@dataclass
class Command:
    """One command as the document writes it, with the ``# ...`` lines after it."""

    kind: str
    """``"bash"`` or ``"python"``."""
    code: str
    """The command (a bash command's continuation lines joined by newlines; its time left out)."""
    first: int
    """Index in the document's lines of the command's first line."""
    last: int
    """Index of its last line."""
    output: list[str]
    """The printed lines the document shows after it (without the ``# ``)."""


@dataclass
class Run:
    """What one command printed and how long it took."""

    code: str
    printed: list[str]
    seconds: float


@dataclass
class Block:
    """A fenced code block: its language (``""`` for none) and the indices of its fences."""

    language: str
    open: int
    close: int


def fenced_blocks(lines: list[str], begin: int, end: int, where: str) -> list[Block]:
    """The fenced code blocks of ``lines[begin:end]`` in order (``where`` names the document in errors)."""
    blocks, i = [], begin
    while i < end:
        match = FENCE.match(lines[i].strip())
        if match:
            close = next((j for j in range(i + 1, end) if lines[j].strip() == "```"), None)
            if close is None:
                raise CommandError(f"{where}:{i + 1}: a code block that does not close")
            blocks.append(Block(match.group(1), i, close))
            i = close
        i += 1
    return blocks


def is_output(line: str) -> bool:
    """Whether ``line`` is a printed line shown after a command (``# ...``)."""
    return line == "#" or line.startswith("# ")


def output_after(lines: list[str], i: int) -> list[str]:
    """The ``# ...`` lines from index ``i`` on, without their ``# ``."""
    out = []
    while i < len(lines) and is_output(lines[i]):
        out.append(lines[i][2:])
        i += 1
    return out


def python_command(lines: list[str], begin: int, end: int) -> Command:
    """The ``python`` block whose lines are ``lines[begin:end]``: one command, its ``# ...`` lines last."""
    last = end - 1
    while last >= begin and is_output(lines[last]):
        last -= 1
    return Command("python", "\n".join(lines[begin : last + 1]), begin, last, output_after(lines, last + 1))


def bash_commands(lines: list[str], begin: int, end: int, where: str) -> list[Command]:
    """The commands of the ``bash`` block whose lines are ``lines[begin:end]`` (a command continues
    over lines ending in a backslash)."""
    commands, i = [], begin
    while i < end:
        if not lines[i].strip():
            i += 1
            continue
        if is_output(lines[i]):
            raise CommandError(f"{where}:{i + 1}: a '#' line that follows no command")
        first = i
        while lines[i].endswith("\\") and i + 1 < end:
            i += 1
        code = "\n".join(lines[first:i] + [TIME.sub("", lines[i])])
        output = output_after(lines, i + 1)
        commands.append(Command("bash", code, first, i, output))
        i += 1 + len(output)
    return commands


def block_commands(lines: list[str], block: Block, where: str) -> list[Command]:
    """The commands of a ``bash`` or ``python`` block (none for another language)."""
    if block.language == "bash":
        return bash_commands(lines, block.open + 1, block.close, where)
    if block.language == "python":
        return [python_command(lines, block.open + 1, block.close)]
    return []


def run_bash(code: str, folder: Path) -> list[str]:
    """Runs ``code`` through bash in ``folder`` with this interpreter's ``arfi`` first on the PATH;
    its printed lines."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run(["bash", "-c", code], cwd=folder, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        why = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise CommandError(f"`{code.splitlines()[0]}` exited {done.returncode}: {why}")
    return done.stdout.splitlines()


def run_python(code: str, folder: Path, namespace: dict | None = None, name: str = "docs") -> list[str]:
    """Runs ``code`` with ``exec`` in ``folder`` (in ``namespace``, a fresh one if None); its printed lines."""
    printed, back = io.StringIO(), os.getcwd()
    os.chdir(folder)  # contextlib.chdir is Python 3.11
    try:
        with contextlib.redirect_stdout(printed):
            exec(compile(code, name, "exec"), {"__name__": "__docs__"} if namespace is None else namespace)
    finally:
        os.chdir(back)
    return printed.getvalue().splitlines()


def run_command(kind: str, code: str, folder: Path, namespace: dict | None = None) -> Run:
    """Runs one command, timed (a ``python`` one in ``namespace``, a fresh one if None)."""
    t = time.perf_counter()
    printed = run_bash(code, folder) if kind == "bash" else run_python(code, folder, namespace)
    return Run(code, printed, time.perf_counter() - t)
