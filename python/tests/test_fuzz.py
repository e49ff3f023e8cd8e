"""Property-based tests: generated bad input to the Python API, the file readers and the CLI.

Every case must end in a result or one of the documented exceptions (``ValueError`` naming the
parameter or file, ``FileNotFoundError``); the CLI must return 0 or 2 with at most one line on
stderr and leave no output file behind when it fails. A case that takes longer than
``DEADLINE`` fails as a hang. ``TRIED`` counts the cases; ``conftest.py`` prints the totals.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from collections import Counter
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import arfi
from arfi import cli
from arfi.io.files import read_arfi_image, read_phases, write_arfi_image

TRIED: Counter[str] = Counter()
DEADLINE = timedelta(seconds=60)
# Generated cases per property: the README's count (about 2270 inputs in all) in the full mode
# (ARFI_FULL_SWEEPS=1, docs/testing.md); a third of them by default, where every strategy and
# every explicit @example still runs (a simulation or an estimate per case makes the counts the
# file's run time).
FULL = bool(os.environ.get("ARFI_FULL_SWEEPS"))
FAST = settings(
    max_examples=300 if FULL else 100, deadline=DEADLINE, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
SLOW = settings(
    max_examples=100 if FULL else 35, deadline=DEADLINE, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)

SIM = arfi.Simulation()
# A complex value cast silently to real (its imaginary part dropped) is a wrong answer, not a warning.
pytestmark = pytest.mark.filterwarnings("error::numpy.exceptions.ComplexWarning")
SHAPE = SIM.arfi_image().shape

NASTY_NUMBERS = [float("nan"), float("inf"), float("-inf"), -1.0, 0.0, 1e-300, 1e300, -1e300, 2**63, -(2**63), 2**64]
NASTY_TOML = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e-300",
    "1e300",
    "-1e300",
    "9223372036854775807",
    "-9223372036854775808",
    '"text"',
    "[]",
    "[1e300, 1e300]",
    "[0, 0, 0]",
    "[nan, nan, nan]",
    "true",
    "{}",
    "[[1]]",
    '""',
    "1",
    "2",
]
NASTY_OBJECTS = [None, "text", "", [], [[]], {}, object(), b"bytes", 1j, [1, "a"], True]


def documented(fn, *args, **kwargs):
    """Calls ``fn``; a ValueError must name what it concerns (a ``name:`` prefix)."""
    try:
        return fn(*args, **kwargs)
    except ValueError as e:
        assert ":" in str(e).split("\n")[0], f"ValueError without the parameter's name: {e}"
    except FileNotFoundError:
        pass
    return None


def nasty_arrays(max_dims: int = 3) -> st.SearchStrategy:
    dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.int8, np.uint8, np.complex128, np.bool_, np.float16])
    return hnp.arrays(dtypes, hnp.array_shapes(min_dims=0, max_dims=max_dims, min_side=0, max_side=40))


def arrays_or_objects(max_dims: int = 3) -> st.SearchStrategy:
    return st.one_of(nasty_arrays(max_dims), st.sampled_from(NASTY_OBJECTS), st.lists(st.floats(), max_size=40))


def image_like() -> st.SearchStrategy:
    """Images of the right shape with nasty content, or arrays of any shape and dtype."""
    values = st.sampled_from([0.0, 1.0, -1.0, 1e-300, 1e300, float("nan"), float("inf")])

    def right_shape(v: float, where: int) -> np.ndarray:
        a = SIM.arfi_image() if where % 3 else np.full(SHAPE, 0.0)
        a = a.copy()
        a.flat[where % a.size] = v
        return a

    right = st.builds(right_shape, values, st.integers(0, 10**6))
    return st.one_of(right, right, nasty_arrays(3))


# --- Scenarios -----------------------------------------------------------------------------------

DEFAULT_TOML = arfi.Scenario.default().to_toml().splitlines()
VALUE_LINES = [i for i, ln in enumerate(DEFAULT_TOML) if "=" in ln and not ln.lstrip().startswith("#")]


@st.composite
def mutated_toml(draw) -> str:
    lines = list(DEFAULT_TOML)
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.sampled_from(VALUE_LINES))
        action = draw(st.sampled_from(["value", "delete", "duplicate", "truncate"]))
        key = lines[i].split("=")[0]
        if action == "value":
            lines[i] = f"{key}= {draw(st.sampled_from(NASTY_TOML))}"
        elif action == "delete":
            lines[i] = ""
        elif action == "duplicate":
            lines.insert(i, lines[i])
        else:
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
    return "\n".join(lines) + "\n"


@FAST
@given(st.one_of(mutated_toml(), st.text(max_size=200)))
def test_any_scenario_text_gives_a_simulation_or_a_value_error(text):
    TRIED["scenario TOML text"] += 1
    s = documented(arfi.Scenario.from_toml, text)
    if s is not None:
        documented(arfi.Simulation, s)


@SLOW
@given(st.binary(max_size=400), st.integers(0, 2))
def test_a_corrupt_scenario_file_gives_a_value_error(tmp_path_factory, data, kind):
    TRIED["scenario file bytes"] += 1
    path = tmp_path_factory.mktemp("s") / "s.toml"
    good = arfi.Scenario.default().to_toml().encode()
    path.write_bytes([data, good[: len(data)], good + data][kind])
    documented(arfi.Scenario.load, path)


# --- Arrays into the API -------------------------------------------------------------------------


@FAST
@given(
    arrays_or_objects(2), st.sampled_from(NASTY_NUMBERS + [0.02]), st.sampled_from([0, 1, -1, 2**64, 1.5, "1", None])
)
def test_any_phases_noise_and_seed_give_an_image_or_a_value_error(phases, noise, seed):
    TRIED["phases, noise, seed"] += 1
    image = documented(SIM.arfi_image, phases, noise, seed)
    if image is not None:
        assert image.shape == SHAPE and np.all(np.isfinite(image))
    documented(SIM.element_phases, phases)
    documented(SIM.condense, phases)
    documented(SIM.field, phases, None)


@SLOW
@given(image_like(), st.one_of(st.none(), arrays_or_objects(1)), st.sampled_from(NASTY_NUMBERS + [3.0, "2", None]))
def test_any_image_to_calibrate_gives_a_calibration_or_a_value_error(image, known, max_width):
    TRIED["calibrate inputs"] += 1
    c = documented(SIM.calibrate, image, known, max_width)
    if c is not None:
        assert np.isfinite(c.broadening_width_mm) and np.isfinite(c.amplitude)


def one_broken(valid: dict, nasty: dict) -> st.SearchStrategy:
    """Keyword arguments: all valid (half the cases) or all valid but one, drawn from its nasty values."""

    @st.composite
    def draw(draw) -> dict:
        kwargs = {k: draw(st.sampled_from(v)) for k, v in valid.items()}
        broken = draw(st.sampled_from([None] * len(nasty) + list(nasty)))
        if broken is not None:
            kwargs[broken] = draw(st.sampled_from(nasty[broken]))
        return kwargs

    return draw()


@SLOW
@given(
    one_broken(
        valid={
            "method": ["lbfgs", "nelder-mead", "pso"],
            "max_evaluations": [1, 30],
            "time_limit_s": [0.5, None],
            "seed": [0, 2**64 - 1],
            "starts": [None, 1, 2],
        },
        nasty={
            "method": ["", "LBFGS", None, 3],
            "max_evaluations": [0, -1, 2**70, 1.5, "5", float("nan")],
            "time_limit_s": [0.0, -1.0, float("nan"), float("inf"), "1"],
            "seed": [-1, 2**64, 2**70, "0", 1.0],
            "starts": [0, -3, 10**9, 2.5],
        },
    ),
    st.one_of(image_like(), st.lists(image_like(), max_size=3)),
)
def test_any_estimation_input_gives_an_estimate_or_a_value_error(kwargs, images):
    TRIED["estimate inputs"] += 1
    e = documented(SIM.estimate, images, **kwargs)
    if e is not None:
        TRIED["estimate inputs accepted"] += 1
        assert np.all(np.isfinite(e.phases_rad))


@SLOW
@given(
    one_broken(
        valid={
            "threshold": [0.0, 5.0],
            "effects": [["amplitude"], ["broadening", "registration_shift"]],
            "max_iterations": [1, 3],
        },
        nasty={
            "threshold": [-1.0, 1e300, float("nan"), "1", None],
            "effects": [[], ["nonsense"], "amplitude", [3], None],
            "max_iterations": [0, -1, 2**70, 1.5, "3"],
        },
    ),
    st.one_of(image_like(), st.lists(image_like(), max_size=3)),
)
def test_any_diagnose_input_gives_a_diagnosis_or_a_value_error(kwargs, images):
    TRIED["diagnose inputs"] += 1
    if kwargs["effects"] is None:  # the whole library: bound the time by the iteration count
        kwargs["max_iterations"] = 1
    d = documented(SIM.diagnose, images, **kwargs)
    if d is not None:
        TRIED["diagnose inputs accepted"] += 1
        assert np.isfinite(d.cost_final) and d.cost_final <= d.cost_initial


EFFECT_NUMBERS = [
    "scale",
    "broadening_width_mm",
    "broadening_anisotropy_mm",
    "dx_mm",
    "dy_mm",
    "offset_rad",
    "slope_x_rad_per_mm",
    "slope_y_rad_per_mm",
    "dz_mm",
    "sound_speed_m_s",
    "attenuation_db_cm_mhz",
]


@pytest.mark.parametrize("key", EFFECT_NUMBERS)
def test_every_nasty_number_for_every_effect_gives_finite_images_or_a_value_error(key):
    """Exhaustive over scalar effects x NASTY_NUMBERS, alone and with a huge scale (CI's generated
    cases found NaN from a width of 1e-300 and from a sound speed of 1e-300)."""
    for value in NASTY_NUMBERS + [5e-324, 1e-10, 1e10]:
        for extra in ({}, {"scale": -1.0}, {"scale": 1e300}):
            TRIED["effect_images inputs"] += 1
            images = documented(SIM.effect_images, {**extra, key: value})
            if images is not None:
                assert all(np.all(np.isfinite(im)) for im in images), {**extra, key: value}


@SLOW
@given(
    st.dictionaries(
        st.sampled_from(EFFECT_NUMBERS + ["group_phases_rad", "dead_groups", "bogus"]),
        st.one_of(st.sampled_from(NASTY_NUMBERS + NASTY_OBJECTS), nasty_arrays(1)),
        max_size=3,
    )
)
@example({"scale": -1.0, "broadening_width_mm": 1e-300})  # found by CI: a width whose square underflows gave NaN
@example({"scale": -1.0, "sound_speed_m_s": 1e-300})  # found by CI: the wavenumber overflowed
def test_any_effects_give_images_or_a_value_error(effects):
    TRIED["effect_images inputs"] += 1
    images = documented(SIM.effect_images, effects)
    if images is not None:
        assert all(np.all(np.isfinite(im)) for im in images)


# --- Files ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def good_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    write_arfi_image(
        d / "m.nii.gz", SIM.arfi_image(), SIM.mr_affine_mm, SIM.mr_volume_shape, {"applied_phases_rad": [0.0] * 16}
    )
    write_arfi_image(d / "m.nii", SIM.arfi_image(), SIM.mr_affine_mm, SIM.mr_volume_shape)
    np.save(d / "p.npy", np.zeros(16))
    return d


def corrupt(data: bytes, how: int, at: int, junk: bytes) -> bytes:
    """Truncated, overwritten, extended or replaced bytes of a good file."""
    at = at % (len(data) + 1)
    return [data[:at], data[:at] + junk + data[at + len(junk) :], data + junk, junk][how]


@SLOW
@given(
    st.sampled_from(["m.nii.gz", "m.nii", "m.json", "p.npy"]),
    st.integers(0, 3),
    st.integers(0, 10**6),
    st.binary(max_size=64),
)
def test_a_corrupt_image_sidecar_or_phase_file_gives_a_value_error(good_files, tmp_path_factory, name, how, at, junk):
    TRIED["corrupt files"] += 1
    d = tmp_path_factory.mktemp("bad")
    for n in ("m.nii.gz", "m.nii", "m.json", "p.npy"):
        data = (good_files / n).read_bytes()
        (d / n).write_bytes(corrupt(data, how, at, junk) if n == name else data)
    if name == "p.npy":
        documented(read_phases, d / name)
    else:
        image = name if name != "m.json" else "m.nii.gz"
        documented(read_arfi_image, d / image)


# --- The command line ----------------------------------------------------------------------------

OPTIONS = {
    "field": ["--phases", "--z-mm"],
    "simulate": ["--phases", "--known-phases", "--noise-rad", "--seed"],
    "calibrate": ["--image", "--max-width-mm"],
    "estimate": [
        "--image",
        "--calibration",
        "--groups",
        "--method",
        "--max-evaluations",
        "--time-limit-s",
        "--seed",
        "--starts",
        "--out-phases",
        "--suggest",
    ],
    "diagnose": ["--image", "--calibration", "--threshold", "--effects"],
    "scenario": ["--default"],
}
VALUES = [
    "nan",
    "inf",
    "-1",
    "0",
    "1e400",
    "-1e300",
    "18446744073709551616",
    "x",
    "",
    "lbfgs",
    "amplitude,bogus",
    "1",
    "16",
    "3",
]


@st.composite
def command_lines(draw, files: list[str]) -> list[str]:
    verb = draw(st.sampled_from(sorted(OPTIONS)))
    argv = [verb]
    for _ in range(draw(st.integers(0, 4))):
        argv.append(draw(st.sampled_from(OPTIONS[verb] + ["--scenario", "--json", "--bogus"])))
        if argv[-1] != "--default" and draw(st.booleans()):
            argv.append(draw(st.sampled_from(VALUES + files)))
    if verb in ("field", "simulate") or draw(st.booleans()):
        argv += ["--out", draw(st.sampled_from(files))]
    return argv


@pytest.fixture(scope="module")
def cli_files(good_files, tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    for n in ("m.nii.gz", "m.json", "p.npy"):
        (d / n).write_bytes((good_files / n).read_bytes())
    (d / "bad.nii.gz").write_bytes((good_files / "m.nii.gz").read_bytes()[:200])
    (d / "bad.toml").write_text("[grid\nspacing_mm = 'x'")
    (d / "huge.toml").write_text("[grid]\nlateral_size_mm = 1e6\n")
    (d / "p.txt").write_text("0.1\nnot a number\n")
    (d / "cal.json").write_text(json.dumps({"broadening_width_mm": "nan", "amplitude": -1}))
    (d / "dir").mkdir()
    names = [
        "m.nii.gz",
        "bad.nii.gz",
        "bad.toml",
        "huge.toml",
        "p.npy",
        "p.txt",
        "cal.json",
        "dir",
        "absent.nii.gz",
        "out.nii.gz",
        "out.npz",
        "out.json",
        "out.npy",
    ]
    return d, [str(d / n) for n in names]


@settings(
    max_examples=300 if FULL else 100,
    deadline=DEADLINE,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    derandomize=True,
)
@given(data=st.data())
def test_any_command_line_exits_0_or_2_with_one_line_and_no_partial_output(cli_files, data):
    d, files = cli_files
    argv = data.draw(command_lines(files))
    TRIED["command lines"] += 1
    outputs = [d / n for n in ("out.nii.gz", "out.npz", "out.json", "out.npy", "out.nii", "out.json")]
    for p in outputs:
        p.unlink(missing_ok=True)
    err, out = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(d)  # relative outputs (a value like "nan" taken as a file name) stay in the test folder
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code = cli.main(argv)
    finally:
        os.chdir(here)
    assert code in (0, 2), (argv, code, err.getvalue())
    TRIED[f"command lines exiting {code}"] += 1
    if code == 2:
        lines = err.getvalue().strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("arfi"), (argv, err.getvalue())
        left = [p.name for p in outputs if p.exists()] + [n for n in os.listdir(d) if n.startswith(".out")]
        assert not left, (argv, left)
