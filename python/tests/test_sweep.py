"""``arfi sweep`` on real dask.distributed clusters (several worker processes)."""

import csv
import json

import numpy as np
import pytest
from distributed import LocalCluster  # a test dependency (pyproject's [test]): missing is a failure

from arfi.analysis.sweep import Trial, TrialResult, run_trial, summarise, trials
from arfi.cli import main


def test_local_cluster_sweep_writes_table_summary_and_plot(tmp_path, capsys):
    out = tmp_path / "sweep"
    code = main(
        [
            "sweep",
            "--noise-rad",
            "0.01",
            "0.05",
            "--images",
            "1",
            "2",
            "--methods",
            "lbfgs",
            "--seeds",
            "1",
            "--workers",
            "2",
            "--out",
            str(out),
            "--json",
            str(tmp_path / "s.json"),
        ]
    )
    assert code == 0, capsys.readouterr().err
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [(float(r["noise_rad"]), int(r["images"])) for r in rows] == [(0.01, 1), (0.01, 2), (0.05, 1), (0.05, 2)]
    assert all(0.0 < float(r["recovered_fraction"]) <= 1.05 for r in rows)
    summary = list(csv.DictReader((out / "summary.csv").open()))
    assert len(summary) == 4 and {s["trials"] for s in summary} == {"1"}
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "report.html").read_text().count("data:image/png;base64,") == 1
    d = json.loads((tmp_path / "s.json").read_text())
    # A trial's result does not depend on the worker process that ran it.
    here = run_trial(Trial(0.05, 2, "lbfgs", 0))
    there = d["trials"][3]
    assert there["recovered_fraction"] == here.recovered_fraction and there["phase_error_rad"] == here.phase_error_rad


def test_existing_cluster_via_scheduler_address(tmp_path):
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        assert (
            main(
                [
                    "sweep",
                    "--noise-rad",
                    "0.02",
                    "--images",
                    "1",
                    "--methods",
                    "lbfgs",
                    "--seeds",
                    "2",
                    "--scheduler",
                    cluster.scheduler_address,
                    "--out",
                    str(tmp_path),
                ]
            )
            == 0
        )
        workers = set(cluster.scheduler.workers)
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [int(r["seed"]) for r in rows] == [0, 1] and len(workers) == 2


def test_more_images_recover_more_in_the_summary():
    rows = [
        TrialResult(Trial(0.02, k, "lbfgs", seed), f, 0.0, 0.0, a, 10, 0.1, 2.7)
        for seed, (k, f, a) in enumerate([(1, 0.5, True), (1, 0.7, True), (3, 0.95, False), (3, 0.97, False)])
    ]
    s = summarise(rows)
    assert [(x.images, x.trials) for x in s] == [(1, 2), (3, 2)]
    assert s[0].recovered_fraction_mean == pytest.approx(0.6) and s[0].recovered_fraction_std == pytest.approx(0.1)
    assert s[0].ambiguous_fraction == 1.0 and s[1].ambiguous_fraction == 0.0
    # A row is the trial's fields, then the outcome's (the CSV's columns).
    assert list(rows[0].to_dict()) == [
        "noise_rad",
        "images",
        "method",
        "seed",
        "case",
        "recovered_fraction",
        "gain",
        "phase_error_rad",
        "ambiguous",
        "evaluations",
        "seconds",
        "broadening_width_mm",
    ]


@pytest.mark.parametrize(
    "args, match",
    [
        (["--noise-rad", "nan"], "noise_rad"),
        (["--images", "0"], "images"),
        (["--methods", "gradient-descent"], "methods"),
        (["--seeds", "0"], "seeds"),
        (["--scheduler", "tcp://127.0.0.1:9"], "scheduler: cannot connect"),
    ],
)
def test_bad_sweep_input_is_one_line_exit_2(tmp_path, capsys, args, match):
    assert main(["sweep", *args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and match in err, err
    assert not (tmp_path / "o" / "sweep.csv").exists()


@pytest.mark.parametrize("first_seed", [-1, 2**64 - 1, 1.0, "0"])
def test_trials_refuse_a_first_seed_the_trials_cannot_derive_their_seeds_from(first_seed):
    with pytest.raises(ValueError, match="^first_seed: must be an integer"):
        trials([0.02], [1], ["lbfgs"], 2, first_seed=first_seed)


def test_trials_cover_every_combination_in_order():
    t = trials([0.01, 0.02], [1, 3], ["lbfgs", "pso"], 2)
    assert len(t) == 16 and t[0] == Trial(0.01, 1, "lbfgs", 0) and t[-1] == Trial(0.02, 3, "pso", 1)
    assert np.all([isinstance(x, Trial) for x in t])


def test_progress_draws_on_a_terminal_only():
    import io

    from arfi.progress import Progress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    pipe, tty = io.StringIO(), Terminal()
    for stream in (pipe, tty):
        bar = Progress("sweep", 4, "trials", stream=stream)
        for _ in range(4):
            bar.advance()
    assert pipe.getvalue() == ""
    lines = tty.getvalue().split("\r")[1:]
    assert len(lines) == 4 and lines[1].startswith("sweep [" + "#" * 15 + "." * 15 + "] 2/4 trials")
    assert lines[-1].endswith(" s\n") and tty.getvalue().count("\n") == 1
