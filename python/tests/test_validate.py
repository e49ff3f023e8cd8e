"""``arfi validate``: the suite's table, report and exit status, as a user runs it."""

import json
import subprocess
import sys
from typing import Any

import pytest

from arfi.validation import suite


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "arfi", "validate", *args], capture_output=True, text=True, timeout=600
    )


def test_validate_writes_its_table_and_report_and_passes_the_layered_cases(tmp_path):
    out = tmp_path / "report"
    r = run("--case", "water", "--case", "bm4", "--out", str(out), "--json", str(tmp_path / "v.json"))
    assert r.returncode == 0, r.stderr
    assert "| water |" in r.stdout and "| bm4 |" in r.stdout and "2 of 2 cases pass" in r.stdout
    for name in ("report.html", "validation.md", "validation.json", "water.png", "bm4.png"):
        assert (out / name).stat().st_size > 0, name
    result = json.loads((tmp_path / "v.json").read_text())
    assert result["passed"] is True
    bm4 = next(c for c in result["cases"] if c["case"] == "bm4")
    # The flat layered skull on its default grid: within the suite's 5 % and 0.5 mm.
    assert abs(bm4["focal_pressure_error"]) < 0.05 and abs(bm4["focal_position_error_mm"]) < 0.5
    assert bm4["step_mm"] == pytest.approx(0.5)
    # Against its exact solution (the full-wave cases name their engine there).
    assert {c["reference"] for c in result["cases"]} == {"exact"}


def test_the_exit_status_says_whether_every_case_passed(tmp_path, monkeypatch, capsys):
    from types import SimpleNamespace

    from arfi.cli import main

    # The shell about the focus meets the suite's tolerances on its default grid (docs/physics.md):
    # exit 0, no FAIL.
    r = run("--case", "shell", "--json", str(tmp_path / "v.json"))
    result = json.loads((tmp_path / "v.json").read_text())
    assert r.returncode == 0 and result["passed"] is True and "FAIL" not in r.stdout, r.stdout
    # The same run with one case failing: exit 1, the case named FAIL in its row and the summary,
    # and the JSON's "passed" false.
    water = suite.run(["water"])[0]
    failing = SimpleNamespace(**{k: getattr(water, k) for k in dir(water) if not k.startswith("_")})
    failing.name, failing.passed = "water", False
    monkeypatch.setattr(suite, "run", lambda cases, progress=None: [water, failing])
    assert main(["validate", "--case", "water", "--json", str(tmp_path / "f.json")]) == 1
    out = capsys.readouterr().out
    assert "| FAIL |" in out and "1 of 2 cases pass (water fail)" in out
    assert json.loads((tmp_path / "f.json").read_text())["passed"] is False


def test_a_tilted_plate_is_held_to_its_own_tolerances_and_says_so(tmp_path):
    r = run("--case", "tilt20", "--json", str(tmp_path / "v.json"))
    case = json.loads((tmp_path / "v.json").read_text())["cases"][0]
    own = case["tolerances"]
    # Looser than the suite's (the march's measured accuracy on bone met obliquely), and printed.
    assert own["focal_pressure"] > suite.TOLERANCES["focal_pressure"]
    assert own["focal_position_mm"] > suite.TOLERANCES["focal_position_mm"]
    assert (
        f"(±{100 * own['focal_pressure']:.0f} %)" in r.stdout
        and "A tolerance in brackets is the case's own" in r.stdout
    )
    # Its pass is judged by its own tolerances.
    assert case["passed"] == (
        abs(case["focal_pressure_error"]) <= own["focal_pressure"]
        and abs(case["focal_position_error_mm"]) <= own["focal_position_mm"]
        and case["axial_error"] <= own["axial_profile"]
        and case["focal_plane_correlation"] >= own["focal_plane_correlation"]
    )
    assert r.returncode == (0 if case["passed"] else 1)


def test_an_unknown_case_or_an_out_that_is_a_file_is_one_line_and_exit_2(tmp_path):
    r = run("--case", "bm9")
    assert r.returncode == 2
    assert r.stderr.strip() == (
        "arfi: error: --case: unknown bm9; the suite has water, bm3, bm4, bm3_solid, shell, bm5, tilt0, tilt10, "
        "tilt20, tilt30, tilt0_shear1500, tilt10_shear1500, tilt20_shear1500, tilt30_shear1500, cap_uniform, "
        "cap_texture1, cap_texture3, head220"
    )
    (tmp_path / "file").write_text("x")
    r = run("--case", "water", "--out", str(tmp_path / "file"))
    assert (
        r.returncode == 2 and r.stderr.strip() == f"arfi: error: --out: {tmp_path / 'file'} exists and is not a folder"
    )
    with pytest.raises(ValueError, match="cases: unknown bm9"):
        suite.run(["bm9"])


def _rows(md: str) -> dict[str, list[Any]]:
    """The numbers of each case's row of a validation table (not its own tolerances, in brackets),
    each with the unit of its last printed digit, then whether it passed."""
    import re

    rows = {}
    for line in md.splitlines():
        raw = [c.strip() for c in line.strip().strip("|").split("|")]
        cells = [re.sub(r"\(.*?\)", "", c).strip() for c in raw]
        if len(cells) == 9 and cells[0] in suite.CASES:
            found = re.findall(r"[-+]?\d+\.\d+", " ".join(cells[1:8]))
            numbers = [(float(v), 10.0 ** -len(v.split(".")[1])) for v in found]
            own = re.findall(r"\(.*?\)", " ".join(raw[1:8]))
            rows[cells[0]] = numbers + [own, cells[8] == "pass"]
    return rows


def test_the_documented_table_is_what_the_suite_prints_now():
    # docs/validation.md shows the suite's table; it must be the current code's, to the last digit printed
    # (give or take one in that digit: floating-point sums may differ between machines).
    from pathlib import Path

    doc = (Path(__file__).parents[2] / "docs" / "validation.md").read_text(encoding="utf-8")
    documented, now = _rows(doc), _rows(suite.table(suite.run()))
    assert set(documented) == set(suite.CASES) == set(now)
    for case in suite.CASES:
        for (d, unit), (n, _) in zip(documented[case][:-2], now[case][:-2]):
            assert abs(d - n) <= 1.01 * unit, f"{case}: documented {documented[case]}, now {now[case]}"
        # The case's own tolerances, in brackets, and whether it passed, exactly.
        assert documented[case][-2:] == now[case][-2:], case
