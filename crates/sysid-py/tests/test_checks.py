"""Checking a fitted linear model from Python gives the numbers of `sysid compare`,
`predict`, `forecast` and `resid` on the same model file and record (a model fitted
with `--detrend linear`, so that the stored trend is removed and restored as the
commands do)."""

import numpy as np
import pandas as pd
import pytest

import sysid
from conftest import DATA, cli, cli_json

HEATING = DATA / "heating_system.csv"


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """`sysid fit lti --order 2 --detrend linear` on the first 400 rows; the held-out
    rows as a file and a DataFrame."""
    dir_ = tmp_path_factory.mktemp("checks")
    frame = pd.read_csv(HEATING)
    train, test = dir_ / "train.csv", dir_ / "test.csv"
    frame.iloc[:400].to_csv(train, index=False)
    frame.iloc[400:].to_csv(test, index=False)
    model = dir_ / "fit.json"
    cli("fit", "lti", "--data", train, "--order", 2, "--detrend", "linear", "--out", model)
    return sysid.LinearModel.load(model), model, test, frame.iloc[400:], dir_


@pytest.mark.parametrize("horizon", ["inf", "5"])
def test_compare_equals_the_command(fitted, horizon):
    model, path, test, frame, _ = fitted
    summary = cli_json("compare", "--model", path, "--data", test, "--horizon", horizon,
                       "--burn-in", 10)
    ours = model.compare(frame, horizon=horizon, burn_in=10)
    assert list(ours.fit_percent.values()) == summary["models"][0]["fit_percent"]


def test_predict_equals_the_command(fitted):
    model, path, test, frame, dir_ = fitted
    out = dir_ / "pred.csv"
    summary = cli_json("predict", "--model", path, "--data", test, "--horizon", 3,
                       "--out", out, "--force")
    ours = model.predict(frame, horizon=3)
    assert list(ours.fit_percent.values()) == summary["fit_percent"]
    assert list(ours.standardised_rms.values()) == summary["standardised_rms"]
    assert ours.loglik == summary["loglik"]
    written = pd.read_csv(out)
    np.testing.assert_allclose(ours.mean["y1"].to_numpy(), written["y1_pred"].to_numpy(),
                               rtol=1e-15)


def test_forecast_equals_the_command(fitted):
    model, path, test, frame, dir_ = fitted
    future = dir_ / "future.csv"
    pd.DataFrame({"u1": np.linspace(5, 7, 20)}).to_csv(future, index=False)
    out = dir_ / "forecast.csv"
    summary = cli_json("forecast", "--model", path, "--data", test, "--steps", 20,
                       "--future-inputs", future, "--level", 0.9, "--out", out, "--force")
    ours = model.forecast(frame, steps=20, future_u=np.linspace(5, 7, 20), alpha=0.1)
    assert ours.z == summary["z"]
    written = pd.read_csv(out)
    mean = [c for c in written.columns if c.endswith("mean") or c == "y1"][0]
    np.testing.assert_allclose(ours.mean["y1"].to_numpy(), written[mean].to_numpy(),
                               rtol=1e-12)


def test_resid_equals_the_command(fitted):
    model, path, test, frame, _ = fitted
    summary = cli_json("resid", "--model", path, "--data", test, "--lags", 12)
    ours = model.resid(frame, lags=12)
    theirs = summary["outputs"][0]
    assert ours.outputs[0]["acf"] == theirs["acf"]
    assert ours.outputs[0]["ljung_box_p_value"] == theirs["ljung_box"]["p_value"]
    assert ours.warnings == summary.get("warnings", [])


def test_a_fit_forecasts_from_the_end_of_its_record():
    heating = pd.read_csv(HEATING)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = sysid.fit_lti(heating.iloc[:400], order=2)
    ahead = res.forecast(steps=5, future_u=np.full(5, 6.0))
    # (the record's times are 0, 2, 4, ... s: the forecast continues them)
    assert ahead.time == [800.0, 802.0, 804.0, 806.0, 808.0]
    direct = res.model.forecast(heating.iloc[:400], steps=5, future_u=np.full(5, 6.0))
    assert ahead == direct
    assert np.all(ahead.lower.to_numpy() < ahead.upper.to_numpy())
