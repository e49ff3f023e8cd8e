"""Safety lines (:mod:`arfi.analysis.safety`): exposures above the limits a user sets are named, with the
place and the tissue, in ``arfi field``'s summary and JSON; within them nothing is printed."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import pytest

from arfi.analysis.safety import exceeded, summary
from arfi.cli import main


def test_each_exposure_above_its_limit_is_named_by_place_and_tissue():
    # Stand-ins with the attributes of Field.focus(): the focal metrics and each tissue's hottest
    # place (whether it is the focus itself is the core's rule, tested with real fields in
    # test_hottest.py and in has-core).
    def place(pa: float, rho_c: float, is_focus: bool = False) -> SimpleNamespace:
        return SimpleNamespace(
            pressure_pa=pa,
            mechanical_index=pa / 1e6 / math.sqrt(0.5),
            isppa_w_cm2=pa**2 / (2 * rho_c) * 1e-4,
            is_focus=is_focus,
        )

    metrics = SimpleNamespace(
        focal_peak_pa=1.2e6, focal_tissue="brain", mechanical_index=1.2 / math.sqrt(0.5), isppa_w_cm2=46.0
    )
    hottest = {"skull": place(1.5e6, 3.1e6 * 1.9), "brain": place(1.19e6, 1.6e6, True), "water": place(0.5e6, 1.5e6)}
    focus = SimpleNamespace(focal_metrics=metrics, hottest=hottest)
    rows = exceeded(focus, mi_limit=1.9, isppa_limit_w_cm2=190.0)
    # The focus: MI 1.70 and 46 W/cm², within; the skull's 1.5 MPa at 0.5 MHz: MI 2.12, above 1.9
    # (its 19 W/cm² within); the brain's hottest sample is the focus itself, not flagged again.
    assert [r.to_dict() for r in rows] == [
        {
            "where": "hottest place",
            "tissue": "skull",
            "quantity": "mechanical_index",
            "value": pytest.approx(1.5 / math.sqrt(0.5)),
            "limit": 1.9,
        }
    ]
    assert summary(rows) == "above the safety lines: MI 2.12 at the hottest place (skull) > 1.9"
    assert [(r.where, r.quantity) for r in exceeded(focus, mi_limit=1.5, isppa_limit_w_cm2=40.0)] == [
        ("focal peak", "mechanical_index"),
        ("focal peak", "isppa_w_cm2"),
        ("hottest place", "mechanical_index"),
    ]
    # A place in the focal peak's tissue hotter than the peak (a side lobe) is flagged.
    hottest["brain"] = place(1.4e6, 1.6e6)
    assert [r.tissue for r in exceeded(focus, mi_limit=1.9, isppa_limit_w_cm2=190.0)] == ["skull", "brain"]
    # No closed focal region: only the hottest places are checked; a field without a volume has none.
    none = SimpleNamespace(focal_metrics=SimpleNamespace(focal_peak_pa=None), hottest=None)
    assert exceeded(none, mi_limit=0.1) == []
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="mi_limit"):
            exceeded(focus, mi_limit=bad)


def test_arfi_field_flags_the_default_focus_and_takes_the_users_limits(tmp_path, capsys):
    # The paper's 70 W phantom experiment: 3.09 MPa at 550 kHz in the phantom, MI 4.16 and
    # I_SPPA 298 W/cm², above the diagnostic guidance (1.9, 190 W/cm²).
    js = tmp_path / "f.json"
    assert main(["field", "--out", str(tmp_path / "f.npz"), "--json", str(js)]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if "safety" in ln]
    assert line == [
        "field: above the safety lines: MI 4.16 at the focal peak (phantom) > 1.9; I_SPPA 298.4 W/cm² at the focal "
        "peak (phantom) > 190"
    ]
    safety = json.loads(js.read_text())["safety"]
    assert (safety["mechanical_index_limit"], safety["isppa_limit_w_cm2"]) == (1.9, 190.0)
    assert [(r["where"], r["quantity"]) for r in safety["exceeded"]] == [
        ("focal peak", "mechanical_index"),
        ("focal peak", "isppa_w_cm2"),
    ]
    # Limits the user sets above the exposure: nothing printed, nothing exceeded.
    assert (
        main(
            [
                "field",
                "--out",
                str(tmp_path / "g.npz"),
                "--json",
                str(js),
                "--mi-limit",
                "5",
                "--isppa-limit-w-cm2",
                "400",
            ]
        )
        == 0
    )
    assert "safety" not in capsys.readouterr().out and json.loads(js.read_text())["safety"]["exceeded"] == []
    # A limit that is not a positive number: one line, exit 2, nothing written.
    assert main(["field", "--out", str(tmp_path / "h.npz"), "--mi-limit", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["arfi: error: --mi-limit: must be a positive number, got -1.0"] and not (tmp_path / "h.npz").exists()
