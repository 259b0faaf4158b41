"""Acceptance 2, 3, 4 and 6: the GIL is released, Ctrl-C stops a run within a second
(with the partial result), the progress callback is called and its exception stops the
run, and the number of threads does not change a result."""

import _thread
import sys
import threading
import time

import numpy as np
import pandas as pd
import pytest

import sysid
from conftest import DATA, OSCILLATOR, REPO


def loops_during(call):
    """How many times a Python thread went round its loop while `call` ran."""
    count, done = [0], threading.Event()

    def spin():
        while not done.is_set():
            count[0] += 1

    thread = threading.Thread(target=spin)
    thread.start()
    try:
        time.sleep(0.05)
        # read with the GIL held, just before and just after the call: the loops the
        # other thread made while the call ran
        before = count[0]
        call()
        after = count[0]
    finally:
        done.set()
        thread.join()
    return after - before


@pytest.fixture(scope="module")
def long_record(oscillator_record):
    return pd.read_csv(oscillator_record)


def test_the_gil_is_released_during_every_computation(long_record, fitted_oscillator):
    heating = pd.read_csv(DATA / "heating_system.csv")
    calls = {
        "particle_filter": lambda: sysid.particle_filter(OSCILLATOR, long_record,
                                                         particles=20000, repeats=3),
        "fit_lti": lambda: sysid.fit_lti(heating, order=3, max_iter=3000, polish="off",
                                         strict=False, tol_nats=0.0),
        "pmmh": lambda: sysid.pmmh(fitted_oscillator, long_record, chains=1,
                                   iterations=400, particles=300, strict=False),
    }
    for name, call in calls.items():
        with np.errstate(all="ignore"):
            import warnings
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                loops = loops_during(call)
        assert loops > 10_000, f"{name}: {loops} loops"
    # the control: a C call that holds the GIL (list.sort of 3e6 Python floats). The
    # other thread can only take its turn once, just before the call (one switch
    # interval, 5 ms): against what it makes when the GIL is free for as long, about 0
    values = np.random.default_rng(1).random(3_000_000).tolist()
    began = time.monotonic()
    held = loops_during(values.sort)
    seconds = time.monotonic() - began
    free = loops_during(lambda: time.sleep(seconds))
    assert held < 0.02 * free, (held, free)


def interrupt_after(seconds):
    timer = threading.Timer(seconds, _thread.interrupt_main)
    timer.start()
    return timer


def test_ctrl_c_stops_a_fit_within_a_second_with_the_partial_result(long_record):
    interrupt_after(1.0)
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt) as caught:
        sysid.fit(OSCILLATOR, long_record, method="em", particles=300, max_iter=100_000)
    assert time.monotonic() - began < 2.0
    partial = caught.value.partial
    assert isinstance(partial, sysid.ModelFitResults)
    assert partial.interrupted
    assert set(partial.params) == {"k", "c"}


def test_ctrl_c_stops_chains_within_a_second_with_the_partial_result(long_record,
                                                                     fitted_oscillator):
    model = sysid.ModelFile.from_string(fitted_oscillator.read_text())
    interrupt_after(1.0)
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt) as caught:
        sysid.pmmh(model, long_record, chains=2, iterations=1_000_000, particles=50,
                   burn_in=10)
    assert time.monotonic() - began < 2.0
    partial = caught.value.partial
    assert isinstance(partial, sysid.Chains)
    assert partial.interrupted
    assert partial.ids == [0, 1]
    assert 0 < partial.iterations < 1_000_000


def test_ctrl_c_stops_a_loop_of_filters_within_a_second(long_record):
    model = sysid.ModelFile(OSCILLATOR)
    interrupt_after(1.0)
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        while True:
            sysid.particle_filter(model, long_record, particles=5000, repeats=0)
    assert time.monotonic() - began < 2.0


def test_ctrl_c_stops_fit_lti_with_the_partial_result():
    heating = pd.read_csv(DATA / "heating_system.csv")
    interrupt_after(0.3)
    with pytest.raises(KeyboardInterrupt) as caught:
        while True:
            sysid.fit_lti(heating, order=6, max_iter=100_000, tol_nats=0.0, polish="off",
                          strict=False)
    partial = getattr(caught.value, "partial", None)
    assert partial is None or isinstance(partial, sysid.LinearFitResults)


def test_progress_true_prints_a_counter_to_stderr(long_record, capsys):
    sysid.fit(OSCILLATOR, long_record, method="em", particles=50, max_iter=20,
              progress=True, strict=False)
    err = capsys.readouterr().err
    assert "fit: 20/20\n" in err


def test_the_progress_callback_is_called_and_its_exception_stops_the_run(long_record):
    seen = []
    sysid.fit(OSCILLATOR, long_record, method="em", particles=50, max_iter=20,
              progress=lambda done, total: seen.append((done, total)), strict=False)
    assert seen and seen[-1] == (20, 20)

    class Enough(Exception):
        pass

    def stop(done, total):
        if done >= 3:
            raise Enough

    began = time.monotonic()
    with pytest.raises(Enough) as caught:
        sysid.fit(OSCILLATOR, long_record, method="em", particles=300, max_iter=100_000,
                  progress=stop)
    assert time.monotonic() - began < 10
    assert caught.value.partial.interrupted


def test_results_do_not_depend_on_the_threads(long_record, fitted_oscillator):
    one = sysid.particle_filter(OSCILLATOR, long_record, particles=20000, seed=4, threads=1)
    two = sysid.particle_filter(OSCILLATOR, long_record, particles=20000, seed=4, threads=2)
    assert one == two
    fit1 = sysid.fit(OSCILLATOR, long_record, max_iter=20, seed=2, threads=1, strict=False)
    fit2 = sysid.fit(OSCILLATOR, long_record, max_iter=20, seed=2, threads=2, strict=False)
    assert fit1 == fit2
    model = sysid.ModelFile(fitted_oscillator)
    c1 = sysid.pmmh(model, long_record, chains=2, iterations=100, particles=200, threads=1,
                    strict=False)
    c2 = sysid.pmmh(model, long_record, chains=2, iterations=100, particles=200, threads=2,
                    strict=False)
    assert c1 == c2


def test_chains_run_apart_concatenate_to_one_run(long_record, fitted_oscillator):
    model = sysid.ModelFile(fitted_oscillator)
    kw = dict(iterations=100, particles=200, seed=3, strict=False)
    whole = sysid.pmmh(model, long_record, chains=4, **kw)
    first = sysid.pmmh(model, long_record, chains=[0, 1], **kw)
    second = sysid.pmmh(model, long_record, chains=[2, 3], **kw)
    assert sysid.Chains.concat([second, first]) == whole


@pytest.mark.parametrize("case", ["robust", "em", "psaem", "direct", "gradient-em",
                                  "simulation"])
def test_ctrl_c_stops_every_fit_method_with_the_partial_result(tmp_path, long_record, case):
    """Every method of ``fit`` stops within 2 s of Ctrl-C (gradient EM: after the
    iteration it is in, whose M-step takes seconds) and keeps the result so far."""
    product = tmp_path / "product.toml"
    product.write_text(OSCILLATOR.read_text().replace("c*v", "k*c*v"))
    tanks = REPO / "examples" / "models" / "cascaded_tanks.toml"
    calls = {
        "robust": lambda: sysid.fit(OSCILLATOR, long_record, max_iter=100_000),
        "em": lambda: sysid.fit(OSCILLATOR, long_record, method="em", max_iter=10**7),
        "psaem": lambda: sysid.fit(OSCILLATOR, long_record, method="psaem", max_iter=10**7),
        "direct": lambda: sysid.fit(product, long_record, starts=200),
        "gradient-em": lambda: sysid.fit(product, long_record, method="em", max_iter=10**7),
        "simulation": lambda: sysid.fit(
            tanks, pd.read_csv(REPO / "examples" / "data" / "cascaded_tanks_est.csv")[["u", "y"]],
            criterion="simulation", starts=100_000),
    }
    interrupt_after(1.5)
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt) as caught:
        calls[case]()
    waited = time.monotonic() - began - 1.5
    assert waited < (10.0 if case == "gradient-em" else 2.0), waited
    partial = caught.value.partial
    assert partial.interrupted
    assert partial.params
