"""The package's layers: modules grouped by what they are, each group importing only the groups
beneath it, and no import cycle among modules. Imports anywhere in a module count (also inside
functions); only ``if TYPE_CHECKING:`` blocks, which run nothing, are skipped.

The layers, bottom up: the extension ``_core``; ``io`` (files in and out); the model at the top
level (``scenario``, ``simulation``, ``cost``, ``estimation``, ``checks``, ``progress``);
``reports`` (figures and pages of results); ``analysis`` and ``validation`` (what is done with the
model); ``cli`` (the verbs)."""

import ast
from pathlib import Path

import arfi

PACKAGE = Path(arfi.__file__).parent

#: What each group may import besides itself.
ALLOWED = {
    "io": {"_core"},
    "model": {"_core", "io"},
    "reports": {"_core", "io", "model"},
    "analysis": {"_core", "io", "model", "reports"},
    "validation": {"_core", "io", "model", "reports", "analysis"},
    "cli": {"_core", "io", "model", "reports", "analysis", "validation"},
}


def module_names() -> dict[str, Path]:
    """Every module of the package by dotted name below ``arfi`` (``io.files``, ``simulation``)."""
    out = {}
    for p in PACKAGE.rglob("*.py"):
        rel = p.relative_to(PACKAGE).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        if parts and parts != ("__main__",):
            out[".".join(parts)] = p
    return out


def group(module: str) -> str:
    head = module.split(".")[0]
    return head if head in ALLOWED or head == "_core" else "model"


def imports(path: Path, known: set[str]) -> set[str]:
    """The arfi modules a file imports (dotted below ``arfi``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped = {
        id(n)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for child in node.body
        for n in ast.walk(child)
    }
    found = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and (node.module + ".").startswith("arfi."):
            base = node.module.removeprefix("arfi").lstrip(".")
            for a in node.names:
                sub = f"{base}.{a.name}".lstrip(".")
                found.add(sub if sub in known or a.name == "_core" else base)
        elif isinstance(node, ast.Import):
            found.update(a.name.removeprefix("arfi.") for a in node.names if a.name.startswith("arfi."))
    return {m for m in found if m}


def dependencies() -> dict[str, set[str]]:
    modules = module_names()
    known = set(modules) | {"_core"}
    return {m: imports(p, known) - {m} for m, p in modules.items()}


def test_each_group_imports_only_the_groups_beneath_it():
    deps = dependencies()
    assert deps["simulation"], "the reader found no imports"
    assert {"io.files", "analysis.prediction", "reports.figures", "validation.suite", "cli.common"} <= set(deps)
    wrong = [
        f"{m} ({group(m)}) imports {d} ({group(d)})"
        for m, ds in sorted(deps.items())
        if m != "__init__"  # the package's own namespace re-exports from every layer
        for d in sorted(ds)
        if group(d) != group(m) and group(d) not in ALLOWED[group(m)]
    ]
    assert not wrong, "\n".join(wrong)


def test_no_module_imports_a_module_that_imports_it_back():
    deps = dependencies()
    # A package's __init__ imported for a submodule is not a dependency on the package's other modules.
    deps = {m: {d for d in ds if d in deps} for m, ds in deps.items()}

    def visit(m: str, path: list[str], done: set[str]) -> None:
        assert m not in path, "import cycle: " + " -> ".join(path[path.index(m) :] + [m])
        if m in done:
            return
        for n in sorted(deps[m]):
            visit(n, path + [m], done)
        done.add(m)

    done: set[str] = set()
    for m in sorted(deps):
        visit(m, [], done)
