import inspect

from arfi import _core


def test_stub_lists_every_public_method_of_the_extension():
    # The .pyi ships with the package; every method the extension exposes must be declared.
    stub = (inspect.getfile(_core).rsplit("/", 1)[0] + "/_core.pyi")
    text = open(stub, encoding="utf-8").read()
    names = [n for n in dir(_core.CoreSimulation) if not n.startswith("_")]
    names += [n for n in dir(_core) if not n.startswith("_") and callable(getattr(_core, n)) and n != "CoreSimulation"]
    missing = [n for n in names if f"def {n}(" not in text]
    assert not missing, missing
