"""Grey-box identification recovers known parameters from a noisy model FRF."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.servo import (
    DEFAULT_IDENT_PARAMS,
    fit_percent,
    get_param,
    identify,
    load_machine,
    open_loop_frf,
    read_frf_csv,
    set_param,
    write_frf_csv,
)

PARAM_RTOL = 0.03  # 3 % on every parameter with 1 % complex noise


def test_fit_percent_definition():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)


def test_identify_recovers_parameters(tmp_path):
    rng = np.random.default_rng(2024)
    nominal = load_machine()
    truth = nominal
    factors = {
        "mechanics.m1": 1.2,
        "mechanics.m2": 0.9,
        "mechanics.k1": 1.3,
        "mechanics.c1": 0.7,
        "mechanics.k2": 1.5,
        "mechanics.c2": 1.4,
    }
    for k, fac in factors.items():
        truth = set_param(truth, k, get_param(nominal, k) * fac)
    f = np.geomspace(10, 30e3, 400)
    y = open_loop_frf(truth, f)
    y = y * (
        1 + 0.01 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    )
    path = tmp_path / "ol.csv"
    write_frf_csv(path, f, y)
    f2, y2 = read_frf_csv(path)
    res = identify(nominal, f2, y2)
    assert res.fit_percent_after > 97.0
    assert res.fit_percent_after > res.fit_percent_before
    for k in DEFAULT_IDENT_PARAMS:
        np.testing.assert_allclose(
            res.parameters[k], get_param(truth, k), rtol=PARAM_RTOL, err_msg=k
        )


def test_bad_frf_file(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("f,re,im\n1,2,3\n")
    with pytest.raises(ConfigError, match="frequency_hz,real,imag"):
        read_frf_csv(p)


def test_frf_csv_with_bom_and_a_dc_row(tmp_path):
    # an independent exporter: Excel-style BOM and a 0 Hz first row
    rows = [(0.0, 1.5, 0.0), (10.0, 1.0, -0.5), (20.0, 0.5, -0.7), (40.0, 0.2, -0.4)]
    text = "frequency_hz,real,imag\n" + "".join(f"{a},{b},{c}\n" for a, b, c in rows)
    p = tmp_path / "frf.csv"
    p.write_bytes(b"\xef\xbb\xbf" + text.encode())
    f, h = read_frf_csv(p)
    np.testing.assert_array_equal(f, [10.0, 20.0, 40.0])
    np.testing.assert_array_equal(h, [1.0 - 0.5j, 0.5 - 0.7j, 0.2 - 0.4j])
    p.write_text(text.replace("10.0,1.0", "-10.0,1.0"))  # negative: still an error
    with pytest.raises(ConfigError, match="positive"):
        read_frf_csv(p)


def test_identify_cli_writes_loadable_machine(tmp_path, capsys):
    import json

    from servosurf.cli import main

    nominal = load_machine()
    truth = set_param(nominal, "mechanics.k2", 3.0e4)
    f = np.geomspace(10, 30e3, 300)
    write_frf_csv(tmp_path / "ol.csv", f, open_loop_frf(truth, f))
    rc = main(
        [
            "identify",
            str(tmp_path / "ol.csv"),
            "--param",
            "mechanics.k2",
            "--out",
            str(tmp_path / "id"),
            "--json",
        ]
    )
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(data["parameters"]["mechanics.k2"], 3.0e4, rtol=1e-6)
    fitted = load_machine(tmp_path / "id" / "fitted-machine.toml")
    np.testing.assert_allclose(fitted.mechanics.k2, 3.0e4, rtol=1e-6)
    assert fitted.mechanics.k1 == nominal.mechanics.k1
    assert fitted.disturbances == nominal.disturbances
