import ast
import inspect

from arfi import _core


def test_stub_lists_every_public_name_of_the_extension():
    # The .pyi ships with the package; every function, class, method and property the extension
    # exposes must be declared in it.
    stub = inspect.getfile(_core).rsplit("/", 1)[0] + "/_core.pyi"
    text = open(stub, encoding="utf-8").read()
    classes = [c for c in dir(_core) if isinstance(getattr(_core, c), type)]
    assert {"CoreSimulation", "CoreCostModel"} <= set(classes)
    missing = [c for c in classes if f"class {c}:" not in text and f"class {c}(" not in text]
    for c in classes:  # each class's own names (an exception's BaseException methods are Python's)
        missing += [f"{c}.{n}" for n in vars(getattr(_core, c)) if not n.startswith("_") and f"def {n}(" not in text]
    missing += [
        n
        for n in dir(_core)
        if not n.startswith("_") and n not in classes and callable(getattr(_core, n)) and f"def {n}(" not in text
    ]
    assert not missing, missing


def test_result_classes_write_every_attribute_to_json_once():
    # to_dict (the JSON) writes the attributes listed in _fields: each result's getters (but model
    # images), no more, no fewer, so an attribute and its JSON key are one name.
    for cls in (
        _core.Calibration,
        _core.Estimate,
        _core.EstimateSupport,
        _core.NuisanceFit,
        _core.NextAcquisition,
        _core.ShiftCandidate,
        _core.Diagnosis,
        _core.DiagnosisStep,
        _core.EffectCandidate,
        _core.AlternativeFit,
        _core.Grid,
        _core.Propagation,
        _core.Reverberation,
    ):
        getters = {n for n, v in vars(cls).items() if type(v).__name__ == "getset_descriptor" and not n.startswith("_")}
        images = {"models", "models_initial", "models_final"}  # model images stay out of the JSON
        assert sorted(cls._fields) == sorted(getters - images), cls.__name__


def _stub_parameters(fn):
    """(name, default) of a stub function's parameters, without self/cls and */**."""
    a = fn.args
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    pairs = list(zip([x.arg for x in positional], defaults)) + list(zip([x.arg for x in a.kwonlyargs], a.kw_defaults))
    return [(n, None if d is None else ast.literal_eval(d)) for n, d in pairs if n not in ("self", "cls")]


def test_stub_signatures_are_the_extensions():
    # Each stubbed function, method and constructor takes the parameters, in order and with the
    # defaults, that the extension's own signature (from its text signature) gives: a renamed or
    # added option cannot leave the .pyi behind.
    stub = inspect.getfile(_core).rsplit("/", 1)[0] + "/_core.pyi"
    tree = ast.parse(open(stub, encoding="utf-8").read())
    functions = [([], f) for f in tree.body if isinstance(f, ast.FunctionDef)]
    for c in (c for c in tree.body if isinstance(c, ast.ClassDef)):
        functions += [([c.name], f) for f in c.body if isinstance(f, ast.FunctionDef) and not f.decorator_list]
    checked, wrong = 0, []
    for owner, fn in functions:
        path = owner + ([] if fn.name == "__init__" else [fn.name])
        obj = _core
        for part in path:
            obj = getattr(obj, part, None)
        if obj is None or (fn.name.startswith("__") and fn.name != "__init__"):
            continue
        if path == ["EstimateOptions"]:  # keywords by name, each defaulting to None: the core's options
            runtime = [(name, None) for name, *_ in _core.EstimateOptions._options]
        else:
            sig = inspect.signature(obj)
            runtime = [
                (p.name, None if p.default is p.empty else p.default)
                for p in sig.parameters.values()
                if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) and p.name not in ("self", "cls")
            ]
        checked += 1
        if runtime != _stub_parameters(fn):
            wrong.append(f"{'.'.join(path)}: stub {_stub_parameters(fn)}, extension {runtime}")
    assert checked > 80 and not wrong, wrong


def test_the_options_part_of_the_stub_is_generated_from_the_extensions_options():
    # EstimateOptions's constructor and attributes are the core's option list; an option added
    # there reaches the stub by running python/tests/stubgen.py, not by hand.
    import stubgen

    stub = inspect.getfile(_core).rsplit("/", 1)[0] + "/_core.pyi"
    text = open(stub, encoding="utf-8").read()
    assert stubgen.updated(text, _core.EstimateOptions._options) == text, "run python python/tests/stubgen.py"
    # The generator sees a change: one more option makes another stub.
    more = [*_core.EstimateOptions._options, ("new_option_mm", "number", True, "a new option")]
    assert "def new_option_mm(self) -> float | None:" in stubgen.updated(text, more)
    names = [name for name, *_ in _core.EstimateOptions._options]
    assert {"method", "prior", "fit_nuisance", "prior_conflict_z"} <= set(names)
    assert all(f"{name} (" in _core.EstimateOptions.describe() for name in names)
