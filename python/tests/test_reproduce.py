import json

import pytest

from arfi.analysis.ladder import RUNGS
from arfi.analysis.reproduce import run_study
from arfi.cli import main


def test_reproduce_writes_table_figures_report_and_the_ladder(tmp_path, capsys):
    out = tmp_path / "study"
    js = tmp_path / "r.json"
    assert (
        main(
            [
                "reproduce",
                "--case",
                "16",
                "--repeats",
                "1",
                "--diversity",
                "3",
                "--method",
                "lbfgs",
                "--out",
                str(out),
                "--json",
                str(js),
            ]
        )
        == 0
    )
    r = json.loads(js.read_text())
    # --json and results.json are the same typed result, its means over the table's rows.
    assert json.loads((out / "results.json").read_text()) == r
    assert r["paper"] == {"recovered_fraction": 0.83, "gain": 0.44, "phase_error_rad": 0.42}
    assert r["mean_recovered_fraction"] == pytest.approx(r["table"][0]["recovered_fraction"])
    # The ladder: every path on the same seed, in order, each with its recovered fraction.
    ladder = {rung["name"]: rung for rung in r["ladder"]}
    assert list(ladder) == RUNGS and all(len(rung["recovered_fractions"]) == 1 for rung in r["ladder"])
    frac = {name: rung["mean_recovered_fraction"] for name, rung in ladder.items()}
    # Seed 0: diversity and loop 2 near the ideal focus; the prediction's 1.3 rad error leaves
    # 0.67, one image with it as prior 0.85; never below the prediction alone (0.02 slack: image noise).
    assert frac["diversity"] > 0.9 and frac["loop 2"] > 0.8
    assert frac["prediction + MR-ARFI"] >= frac["CT-like prediction alone"] - 0.02
    assert "recovered fraction by path: single image (paper)" in capsys.readouterr().out
    assert (out / "fig11_ladder.png").stat().st_size > 5000
    row = r["table"][0]
    for key in (
        "evaluations",
        "seconds",
        "final_cost",
        "broadening_width_mm",
        "recovered_fraction",
        "gain",
        "phase_error_rad",
    ):
        assert key in row
    # Three known diversity images at 0.02 rad decide the aberration (one image alone hardly tells the aberration from
    # its twin).
    assert row["recovered_fraction"] > 0.9
    assert row["broadening_width_mm"] == pytest.approx(2.7, abs=0.15)
    for name in (
        "fig2_calibration",
        "fig3_optimisation_example",
        "fig4_aberrations",
        "fig5_beam_patterns",
        "fig6_images",
        "fig7_profiles",
        "fig8_convergence",
        "fig9_phases",
        "fig10_focal",
    ):
        assert (out / f"{name}.png").stat().st_size > 5000
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 10 and "Table 1" in html and "Paths to a correction" in html
    assert (out / "table.csv").read_text().startswith("experiment,")


def test_reproduce_rejects_bad_options(tmp_path, capsys):
    assert main(["reproduce", "--case", "16", "--repeats", "0", "--out", str(tmp_path / "x")]) == 2
    assert main(["reproduce", "--case", "17", "--out", str(tmp_path / "x")]) == 2
    assert main(["reproduce", "--case", "16", "--loop2", "-1", "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


def test_reproduce_1024_with_loop2_never_keeps_a_worse_correction(tmp_path, capsys):
    js = tmp_path / "r.json"
    assert (
        main(
            [
                "reproduce",
                "--case",
                "1024",
                "--repeats",
                "1",
                "--loop2",
                "1",
                "--method",
                "lbfgs",
                "--no-ladder",
                "--out",
                str(tmp_path / "study"),
                "--json",
                str(js),
            ]
        )
        == 0
    )
    r = json.loads(js.read_text())
    row = r["table"][0]
    assert r["loop2_iterations"] == 1 and row["images"] == 2 and row["loop2_kept"] in (0, 1)
    assert row["focal_corrected_rad"] >= row["focal_aberrated_rad"] - 1e-12
    assert "loop2_kept" in (tmp_path / "study" / "table.csv").read_text().splitlines()[0]
    assert ("1 of 1 final estimates still flagged ambiguous" in capsys.readouterr().out) == row["ambiguous"]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"repeats": 0}, "repeats"),
        ({"repeats": 2.5}, "repeats"),
        ({"diversity": -1}, "diversity"),
        ({"loop2_iterations": 21}, "loop2_iterations"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**64 - 1}, "seed"),
        ({"noise_rad": float("nan")}, "noise_rad"),
        ({"noise_rad": "0.02"}, "noise_rad"),
        ({"case": 17}, "case"),
    ],
)
def test_run_study_refuses_bad_arguments_naming_them_and_writes_nothing(tmp_path, kwargs, match):
    args = {"case": 16, "repeats": 1, **kwargs}
    with pytest.raises(ValueError, match=f"^{match}: "):
        run_study(args.pop("case"), args.pop("repeats"), tmp_path / "x", **args)
    assert not (tmp_path / "x").exists()


def test_a_study_that_fails_midway_leaves_no_output_folder(tmp_path):
    # The estimator is refused by the core only once the first repeat reaches it: still nothing written.
    with pytest.raises(ValueError, match="method"):
        run_study(16, 1, tmp_path / "x", method="gradient-descent", progress=False)
    assert not (tmp_path / "x").exists()
