"""The keywords of ``sysid.fit`` are the library's settings: a keyword left ``None``
takes the library's default (``sysid.fit_defaults()``, the defaults ``sysid fit --help``
shows), and a keyword the method that runs does not read raises ``OptionError`` naming
the keyword and the method, as the command line refuses the flag."""

import inspect
import re

import pandas as pd
import pytest

import sysid
from conftest import OSCILLATOR, cli

SETTINGS = ["method", "particles", "smoother", "max_iter", "starts", "polish",
            "extrapolate", "patience", "spread"]


def help_defaults(*command):
    """``{flag: default}`` as ``--help`` prints them."""
    text = cli(*command, "--help").stdout
    found = {}
    for line in text.splitlines():
        m = re.match(r"\s+--([a-z-]+) <[A-Z_]+>.*\[default: ([^\]]+)\]", line)
        if m:
            found[m.group(1).replace("-", "_")] = m.group(2)
    return found


def as_flag_value(v):
    if isinstance(v, bool):
        return "on" if v else "off"
    return str(v)


def test_the_keywords_left_out_take_the_defaults_the_command_line_shows():
    defaults = sysid.fit_defaults()
    assert sorted(defaults) == sorted(SETTINGS)
    shown = help_defaults("fit")
    for name, value in defaults.items():
        assert shown[name] == as_flag_value(value), name
    signature = inspect.signature(sysid.fit).parameters
    for name in SETTINGS:
        assert signature[name].default is None, name
    assert signature["criterion"].default == shown["criterion"]
    assert signature["seed"].default == int(shown["seed"])


@pytest.mark.parametrize("keywords, method", [
    ({"particles": 50}, "the direct likelihood search"),
    ({"max_iter": 5}, "the direct likelihood search"),
    ({"method": "em", "starts": 2}, "gradient EM"),
])
def test_a_keyword_the_method_does_not_read_is_refused(tmp_path, oscillator_record,
                                                       keywords, method):
    product = tmp_path / "product.toml"
    product.write_text(OSCILLATOR.read_text().replace("c*v", "k*c*v"))
    refused = [k for k in keywords if k != "method"][0]
    with pytest.raises(sysid.OptionError) as e:
        sysid.fit(product, pd.read_csv(oscillator_record), **keywords)
    assert e.value.option == refused
    assert str(e.value).startswith(f"{refused} does not apply to {method}")
    # the command line refuses the flag with the same sentence, in its own spelling
    flags = [a for k, v in keywords.items() for a in (f"--{k.replace('_', '-')}", v)]
    run = cli("fit", "--model", product, "--data", oscillator_record, *flags,
              "--out", tmp_path / "x.toml", check=False)
    assert run.returncode == 2
    assert f"--{refused.replace('_', '-')} does not apply to {method}" in run.stderr


def test_the_affine_methods_refuse_alike(oscillator_record):
    data = pd.read_csv(oscillator_record)
    with pytest.raises(sysid.OptionError, match="extrapolate does not apply to plain particle EM"):
        sysid.fit(OSCILLATOR, data, method="em", extrapolate=False)
    with pytest.raises(sysid.OptionError, match="smoother does not apply to particle SAEM"):
        sysid.fit(OSCILLATOR, data, method="psaem", smoother="ffbsi-reject")
    with pytest.raises(sysid.OptionError,
                       match="max_iter does not apply to the simulation-error fit"):
        sysid.fit(OSCILLATOR, data, criterion="simulation", max_iter=3)


def test_fit_lti_signature_shows_the_library_defaults():
    from sysid import _sysid
    library = dict(_sysid.fit_lti_defaults())
    signature = inspect.signature(sysid.fit_lti).parameters
    for name, value in library.items():
        assert signature[name].default == value, name
    shown = help_defaults("fit", "lti")
    for name in ["weighting", "initial", "accelerate", "polish", "std_errors", "select",
                 "max_iter", "tol_nats", "min_variance", "min_output_noise"]:
        value = library[name]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            assert float(shown[name]) == value, name
        else:
            assert shown[name] == value, name
    assert shown["detrend"] == "none" and library["detrend"] is None


def test_fit_lti_refuses_the_start_s_settings_with_a_start_model():
    from conftest import DATA
    y = pd.read_csv(DATA / "ar1.csv")
    start = DATA / "ar1_start.json"
    with pytest.raises(sysid.OptionError, match="weighting does not apply to EM from the given start"):
        sysid.fit_lti(y, init=start, weighting="cva")
    with pytest.raises(sysid.OptionError, match="select does not apply to a fit of one order"):
        sysid.fit_lti(y, order=1, select="aic")
