"""A model file's noise-free simulation, ``ModelFile.compare`` and the simulation-error
fit (``fit(criterion="simulation")``) give the command line's numbers, on the measured
cascaded-tanks record."""

import numpy as np
import pandas as pd
import pytest

import sysid
from conftest import REPO, cli, cli_json

EXAMPLES = REPO / "examples"
TANKS = EXAMPLES / "models" / "cascaded_tanks.toml"
FITTED = EXAMPLES / "models" / "cascaded_tanks_fitted.toml"
EST = EXAMPLES / "data" / "cascaded_tanks_est.csv"
VAL = EXAMPLES / "data" / "cascaded_tanks_val.csv"


def test_compare_equals_the_command():
    model = sysid.ModelFile(FITTED)
    val = pd.read_csv(VAL)
    ours = model.compare(val[["u", "y"]], initial_samples=5)
    theirs = cli_json("compare", "--model", FITTED, "--data", VAL, "--initial-samples", 5)
    row = theirs["models"][0]
    assert ours.rms["y"] == row["rms"][0]
    assert ours.fit_percent["y"] == row["fit_percent"][0]
    assert ours.initial_state == row["initial_state"]
    assert ours.rms["y"] <= 0.34  # better than every published figure
    assert ours.outputs.shape == (1024, 1)


def test_simulate_equals_the_command(tmp_path):
    model = sysid.ModelFile(FITTED)
    u = pd.read_csv(VAL)["u"].to_numpy()
    states, outputs = model.simulate(u)
    out = tmp_path / "sim.csv"
    cli("simulate", "--model", FITTED, "--data", VAL, "--noise-free", "--states", "--out", out)
    theirs = pd.read_csv(out)
    assert np.array_equal(outputs[:, 0], theirs["y"].to_numpy())
    assert np.array_equal(states, theirs[["h1", "h2"]].to_numpy())
    # from a given initial state, and the errors
    states2, _ = model.simulate(u, x0=[30.0, 4.5])
    assert states2[0].tolist() == [30.0, 4.5]
    with pytest.raises(sysid.OptionError):
        model.simulate()


def test_simulation_error_fit_equals_the_command(tmp_path):
    est = pd.read_csv(EST)
    ours = sysid.fit(TANKS, est[["u", "y"]], criterion="simulation", starts=3, seed=4)
    out = tmp_path / "fit.toml"
    theirs = cli_json("fit", "--model", TANKS, "--data", EST, "--criterion", "simulation",
                      "--starts", 3, "--seed", 4, "--out", out)
    assert ours.rms["y"] == theirs["rms"][0]
    assert ours.params == theirs["estimate"]
    assert ours.bse == theirs["standard_errors"]
    assert ours.warnings == theirs["warnings"]
    assert [r["rms"] for r in ours.runs] == [r["rms"] for r in theirs["runs"]]
    assert ours.model.params == sysid.ModelFile(out).params
    with pytest.raises(sysid.OptionError) as e:
        sysid.fit(TANKS, est[["u", "y"]], criterion="prediction")
    assert e.value.option == "criterion"


def test_predict_equals_the_command(tmp_path):
    model = sysid.ModelFile(FITTED)
    val = pd.read_csv(VAL)
    mean, sd = model.predict(val[["u", "y"]], horizon=3, particles=500, seed=9)
    out = tmp_path / "p.csv"
    cli("predict", "--model", FITTED, "--data", VAL, "--horizon", 3, "--particles", 500,
        "--seed", 9, "--out", out)
    theirs = pd.read_csv(out)
    assert np.array_equal(mean[:, 0], theirs["y_pred"].to_numpy())
    assert np.array_equal(sd[:, 0], theirs["y_sd"].to_numpy())
    with pytest.raises(sysid.OptionError) as e:
        model.predict(val[["u", "y"]], horizon=0)
    assert e.value.option == "horizon"
