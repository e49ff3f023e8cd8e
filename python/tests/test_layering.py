"""The package's modules form no import cycle: no module imports a module that imports it back,
directly or through others. Imports anywhere in a module count (also inside functions); only
``if TYPE_CHECKING:`` blocks, which run nothing, are skipped."""

import ast
from pathlib import Path

import arfi

PACKAGE = Path(arfi.__file__).parent


def imports(path: Path) -> set[str]:
    """The arfi modules a file imports."""
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
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("arfi."):
            found.add(node.module.split(".")[1])
        elif isinstance(node, ast.ImportFrom) and node.module == "arfi":
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.Import):
            found.update(a.name.split(".")[1] for a in node.names if a.name.startswith("arfi."))
    return found


def test_no_module_imports_a_module_that_imports_it_back():
    modules = {p.stem: p for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", "__main__")}
    deps = {m: imports(p) & set(modules) - {m} for m, p in modules.items()}
    assert deps["simulation"], "the reader found no imports"

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
