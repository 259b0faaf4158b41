"""Acceptance 1: the Python functions give the command line's numbers for the same
data, options and seed: `==` for loglik, the particle filter, n4sid and PMMH draws;
the model entries, log-likelihood and standard errors of `fit lti` and `fit --model`."""

import json

import numpy as np
import pandas as pd
import pytest

import sysid
from conftest import DATA, OSCILLATOR, cli, cli_json

ENTRIES = ["a", "b", "c", "d", "h", "q", "r", "s", "mu", "p1"]


def assert_same_model(python, path):
    """Every matrix entry of a model equals the written file's to 1e-12 relative (in
    fact to the bit: the same library call on the same numbers)."""
    ours = json.loads(python.to_json())
    theirs = json.loads(path.read_text())
    for key in ENTRIES:
        if key in theirs:
            np.testing.assert_allclose(np.array(ours[key], dtype=float),
                                       np.array(theirs[key], dtype=float), rtol=1e-12, atol=0)
    assert ours.get("initial") == theirs.get("initial")
    assert ours["metadata"]["loglik"] == theirs["metadata"]["loglik"]


def cli_fit(tmp_path, *args):
    out = tmp_path / "fit.json"
    summary = cli_json("fit", "lti", *args, "--out", out)
    return out, summary


def test_fit_lti_on_the_tour_data_equals_the_command(tmp_path, tour_record):
    out, summary = cli_fit(tmp_path, "--data", tour_record, "--order", 8, "--max-iter", 10000)
    with pytest.warns(sysid.SysidWarning) if summary["warnings"] else _nothing():
        res = sysid.fit_lti(pd.read_csv(tour_record), order=8, max_iter=10000)
    assert_same_model(res.model, out)
    assert res.llf == summary["loglik"]
    assert res.iterations == summary["iterations"]
    assert res.termination == summary["termination"]
    assert res.warnings == summary["warnings"]


def test_fit_lti_on_the_nile_equals_the_command_with_standard_errors(tmp_path):
    start = DATA / "nile_start.json"
    out, summary = cli_fit(tmp_path, "--data", DATA / "nile.csv", "--init", start,
                           "--fix", "A", "--fix", "C", "--initial", "diffuse")
    res = sysid.fit_lti(pd.read_csv(DATA / "nile.csv"), init=start, fix=["A", "C"],
                        initial="diffuse")
    assert_same_model(res.model, out)
    assert res.llf == summary["loglik"]
    errors = [p["std_error"] for p in summary["parameters"]]
    assert len(errors) == 2
    np.testing.assert_allclose(res.bse.to_numpy(), errors, rtol=1e-12, atol=0)
    assert list(res.params.index) == [p["name"] for p in summary["parameters"]]
    # statsmodels' local level on the Nile: sigma2.level 1469.1, sigma2.irregular 15098.5
    np.testing.assert_allclose(sorted(res.params.to_numpy()), [1469.1, 15098.5], rtol=1e-3)


def test_fit_lti_with_a_split_range_and_mean_detrending_equals_the_command(tmp_path):
    out, summary = cli_fit(tmp_path, "--data", DATA / "heating_system.csv", "--order", "1..3",
                           "--detrend", "mean", "--split", 0.5, "--select", "validation")
    res = sysid.fit_lti(pd.read_csv(DATA / "heating_system.csv"), order=range(1, 4),
                        detrend="mean", split=0.5, select="validation")
    assert_same_model(res.model, out)
    table = res.table
    assert list(table.index) == [r["order"] for r in summary["order_table"]["orders"]]
    assert list(table["loglik"]) == [r["loglik"] for r in summary["order_table"]["orders"]]
    assert res.validation["simulation_fit_percent"] == \
        summary["validation"]["simulation_fit_percent"]


def test_loglik_equals_the_command():
    model = DATA / "heating_first_order.json"
    data = DATA / "heating_system.csv"
    theirs = cli_json("loglik", "--model", model, "--data", data)["loglik"]
    assert sysid.loglik(model, pd.read_csv(data)) == theirs


def test_n4sid_equals_the_command(tmp_path):
    out = tmp_path / "n4.json"
    data = DATA / "heating_system.csv"
    summary = cli_json("n4sid", "--data", data, "--order", "auto", "--block-rows", 3,
                       "--out", out)
    with pytest.warns(sysid.SysidWarning):
        res = sysid.n4sid(pd.read_csv(data), "auto", block_rows=3)
    assert res.order == summary["order"]
    assert list(res.singular_values) == summary["singular_values"]
    assert res.spectral_radius == summary["spectral_radius"]
    assert res.warnings == summary["warnings"]
    assert res.weighting == summary["weighting"]
    assert [(w["weighting"], w["prediction_fit"], w["stable"]) for w in res.weightings] == [
        (w["weighting"], w["prediction_fit"], w["stable"]) for w in summary["weightings"]]
    assert len(res.weightings) == 3
    ours, theirs = json.loads(res.model.to_json()), json.loads(out.read_text())
    for key in ENTRIES:
        if key in theirs:
            assert ours[key] == theirs[key], key


@pytest.mark.parametrize("repeats", [0, 4])
def test_particle_filter_equals_the_command(oscillator_record, repeats):
    summary = cli_json("pf", "--model", OSCILLATOR, "--data", oscillator_record,
                       "--particles", 2000, "--seed", 3, "--repeats", repeats)
    pf = sysid.particle_filter(sysid.ModelFile(OSCILLATOR), pd.read_csv(oscillator_record),
                               particles=2000, seed=3, repeats=repeats)
    assert pf.loglik == summary["loglik"]
    assert pf.loglik_sd == summary["diagnostics"]["loglik_sd"]
    assert pf.loglik_sd_method == summary["diagnostics"]["loglik_sd_method"]
    assert pf.loglik_sd_method == ("single-run" if repeats == 0 else "repeats")
    assert pf.loglik_sd_single_run == summary["diagnostics"]["loglik_sd_single_run"]
    assert pf.repeat_logliks == summary["diagnostics"]["repeat_logliks"]
    assert len(pf.repeat_logliks) == repeats
    assert pf.min_ess == summary["diagnostics"]["min_ess"]
    assert pf.warnings == summary["warnings"]


def test_particle_filter_means_equal_the_command_s_file(tmp_path, oscillator_record):
    out = tmp_path / "pf.csv"
    cli("pf", "--model", OSCILLATOR, "--data", oscillator_record, "--particles", 500,
        "--seed", 2, "--repeats", 0, "--out", out)
    pf = sysid.particle_filter(OSCILLATOR, pd.read_csv(oscillator_record), particles=500,
                               seed=2, repeats=0)
    written = pd.read_csv(out)
    np.testing.assert_array_equal(pf.means, written[["p", "v"]].to_numpy())


def test_fit_of_a_model_file_equals_the_command(tmp_path, oscillator_record):
    out = tmp_path / "fit.toml"
    summary = cli_json("fit", "--model", OSCILLATOR, "--data", oscillator_record,
                       "--max-iter", 40, "--seed", 1, "--out", out)
    res = sysid.fit(OSCILLATOR, pd.read_csv(oscillator_record), max_iter=40, seed=1,
                    strict=False)
    written = sysid.ModelFile(out)
    for name, value in written.params.items():
        assert res.params[name] == pytest.approx(value, rel=1e-12, abs=0)
    assert res.method == "robust"
    assert res.llf == summary.get("loglik_estimate", summary.get("loglik"))
    # the polish's curvature, probed along its flattest directions, on both faces
    assert res.bse == summary.get("standard_errors")


def test_direct_fit_of_a_file_that_is_not_affine_equals_the_command(tmp_path,
                                                                  oscillator_record):
    product = tmp_path / "product.toml"
    product.write_text(OSCILLATOR.read_text().replace("c*v", "k*c*v"))
    out = tmp_path / "fit.toml"
    summary = cli_json("fit", "--model", product, "--data", oscillator_record, "--starts", 2,
                       "--seed", 4, "--out", out)
    res = sysid.fit(product, pd.read_csv(oscillator_record), starts=2, seed=4, strict=False)
    written = sysid.ModelFile(out)
    for name, value in written.params.items():
        assert res.params[name] == pytest.approx(value, rel=1e-12, abs=0)
    assert res.method == summary["method"] == "direct"
    assert res.llf == summary["loglik_estimate"]
    assert res.bse == summary.get("standard_errors")
    assert res.warnings == summary["warnings"]


@pytest.mark.parametrize("extrapolate", [True, False])
def test_fit_extrapolate_equals_the_command_s(tmp_path, oscillator_record, extrapolate):
    # 80 iterations: the first jump is due at 50, within the first three quarters
    out = tmp_path / "fit.toml"
    summary = cli_json("fit", "--model", OSCILLATOR, "--data", oscillator_record,
                       "--max-iter", 80, "--starts", 2, "--extrapolate",
                       "on" if extrapolate else "off", "--out", out)
    res = sysid.fit(OSCILLATOR, pd.read_csv(oscillator_record), max_iter=80, starts=2,
                    extrapolate=extrapolate, strict=False)
    written = sysid.ModelFile(out)
    for name, value in written.params.items():
        assert res.params[name] == pytest.approx(value, rel=1e-12, abs=0)
    assert (summary["refinement"]["jumps_tried"] > 0) == extrapolate


def test_pmmh_draws_equal_the_command_s(tmp_path, oscillator_record):
    out = tmp_path / "chains.json"
    fitted = tmp_path / "osc.toml"
    # the guide's order: fit, then sample around the fit
    cli("fit", "--model", OSCILLATOR, "--data", oscillator_record, "--max-iter", 40,
        "--out", fitted)
    summary = cli_json("pmmh", "--model", fitted, "--data", oscillator_record, "--iters", 200,
                       "--chains", 2, "--particles", 200, "--out", out)
    post = sysid.pmmh(fitted, pd.read_csv(oscillator_record), chains=2, iterations=200,
                      particles=200, strict=False)
    assert json.loads(post.to_json())["chains"] == json.loads(out.read_text())["chains"]
    assert post.acceptance == summary["acceptance"]
    assert post.warnings == summary["warnings"]
    assert post.draws.shape == (2, 160, 2)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
