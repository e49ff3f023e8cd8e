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
    ):
        getters = {n for n, v in vars(cls).items() if type(v).__name__ == "getset_descriptor" and not n.startswith("_")}
        images = {"models", "models_initial", "models_final"}  # model images stay out of the JSON
        assert sorted(cls._fields) == sorted(getters - images), cls.__name__
