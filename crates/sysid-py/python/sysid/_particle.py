"""Your own nonlinear model as a model file (docs/model-format.md), compiled in Rust,
and the particle methods on it: ``particle_filter``, ``fit`` and ``pmmh``."""

import json
import os

import numpy as np

from . import _sysid
from ._data import signals
from ._errors import OptionError
from ._linear import _same, _write_new
from ._trust import partial_as, report


class ModelFile:
    """A nonlinear state-space model file (``.toml``): its equations, parameters and
    noise. ``ModelFile(path)`` reads one, ``ModelFile.from_string(text)`` takes the
    text. A bad file raises ``ModelFileError`` with the line and column."""

    def __init__(self, path):
        path = os.fspath(path)
        with open(path, encoding="utf-8") as f:
            self._set(f.read(), path)

    @classmethod
    def from_string(cls, text, origin="<string>"):
        model = cls.__new__(cls)
        model._set(text, origin)
        return model

    def _set(self, text, origin):
        self.text, self.origin = text, origin
        self._compiled = _sysid.CompiledModel(text, origin)

    def __getstate__(self):
        return {"text": self.text, "origin": self.origin}

    def __setstate__(self, state):
        self._set(state["text"], state["origin"])

    def __eq__(self, other):
        return isinstance(other, ModelFile) and self.text == other.text

    @property
    def param_names(self):
        """The free parameters (those not ``fixed = true``)."""
        return self._compiled.free_names()

    @property
    def params(self):
        """The free parameters' values in the file, by name."""
        return dict(zip(self.param_names, self._compiled.free_values()))

    @property
    def states(self):
        return self._compiled.names()[0]

    @property
    def inputs(self):
        return self._compiled.names()[1]

    @property
    def outputs(self):
        return self._compiled.names()[2]

    def save(self, path, overwrite=False):
        """Writes the file's text (refuses to replace a file unless ``overwrite``)."""
        _write_new(path, self.text, overwrite)

    def _signals(self, data, u, time):
        return signals(data, u, time, model_names=(self.inputs, self.outputs))

    def simulate(self, u=None, *, steps=None, x0=None):
        """``sysid simulate --model --noise-free``: the noise-free simulation (every noise
        term zero) of the inputs ``u`` (``(T,)`` or ``(T, m)``; for a model without
        inputs give ``steps``) from ``x0`` or the file's initial means. Returns
        ``(states, outputs)``, arrays ``(T, n)`` and ``(T, p)``."""
        if u is None:
            if steps is None:
                raise OptionError("give the inputs u, or steps for a model without inputs", "steps")
            u = np.zeros((int(steps), 0))
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u.reshape(-1, 1)
        steps = u.shape[0] if steps is None else int(steps)
        x0 = None if x0 is None else [float(v) for v in x0]
        return _sysid.simulate_noise_free(self._compiled, np.ascontiguousarray(u), steps, x0)

    def predict(self, data, u=None, *, horizon=1, particles=5000, seed=1, time=None):
        """``sysid predict --model``: the ``horizon``-step-ahead predictions of a record's
        outputs by a bootstrap particle filter (``y_t`` given the outputs up to
        ``t - horizon``). Returns ``(mean, sd)``, arrays ``(T, p)``; ``sd`` includes the
        measurement noise. Their Monte Carlo error is about ``sd / sqrt(particles)``."""
        s = self._signals(data, u, time)
        return _sysid.predict_particles(self._compiled, s.y, s.u, horizon, particles, seed)

    def compare(self, data, u=None, *, initial_samples=None, x0=None, burn_in=0, time=None):
        """``sysid compare --model``: the noise-free simulation of a record's inputs,
        scored against its outputs (RMS and MATLAB's fit per output), from the initial
        state that minimises the simulation error over the first ``initial_samples``
        samples (the whole record by default), or from ``x0``."""
        s = self._signals(data, u, time)
        x0 = None if x0 is None else [float(v) for v in x0]
        raw = _sysid.compare_simulation(self._compiled, s.y, s.u, initial_samples, x0, burn_in)
        return SimulationComparison(raw, self.outputs)

    def __repr__(self):
        return f"ModelFile({self.origin!r}, params={self.params})"


def _model(model):
    return model if isinstance(model, ModelFile) else ModelFile(model)


class FilterResults:
    """``sysid pf``: the log-likelihood estimate, its Monte Carlo sd (from the run's
    genealogy, ``loglik_sd_method == "single-run"``, or from repeats), the filtered means
    and the ESS of every step, and the warnings."""

    def __init__(self, raw, states):
        self._raw = dict(raw)
        self.states = list(states)
        self.loglik = raw["loglik"]
        self.loglik_sd = raw["loglik_sd"]
        self.loglik_sd_method = raw["loglik_sd_method"]
        self.loglik_sd_single_run = raw["loglik_sd_single_run"]
        self.repeat_logliks = list(raw["repeat_logliks"])
        self.resampled_steps = raw["resampled_steps"]
        self.means = np.asarray(raw["means"], dtype=float)
        self.ess = np.asarray(raw["ess"], dtype=float)
        self.min_ess = raw["min_ess"]
        self.min_ess_step = raw["min_ess_step"]
        self.warnings = list(raw["warnings"])

    def __reduce__(self):
        return (FilterResults, (self._raw, self.states))

    def __repr__(self):
        sd = "" if self.loglik_sd is None else f" (sd {self.loglik_sd:.3g})"
        return (f"<FilterResults loglik={self.loglik:.6g}{sd} steps={len(self.ess)} "
                f"warnings={len(self.warnings)}>")

    def __eq__(self, other):
        strip = lambda raw: {k: v for k, v in raw.items() if k != "seconds"}  # noqa: E731
        return isinstance(other, FilterResults) and _same(strip(self._raw), strip(other._raw))


def particle_filter(model, data, u=None, *, particles=1000, seed=1, resample="systematic",
                    ess=1.0, repeats=0, time=None, progress=None, threads=None, strict=False):
    """``sysid pf``: the bootstrap particle filter on a model file at its values.

    The log-likelihood's Monte Carlo sd comes from the run's own genealogy (one
    filter's cost; measured 10-17 % low, and blind to rare losses of the state);
    ``repeats=N`` runs N more independent filters and takes their sd instead."""
    model = _model(model)
    s = model._signals(data, u, time)
    raw = _sysid.particle_filter(model._compiled, s.y, s.u, s.time, particles, seed, resample,
                                 ess, repeats, progress, threads)
    return report(FilterResults(raw, model.states), strict, "particle_filter")


class ModelFitResults:
    """``sysid fit --model``: the fitted model file, the estimates, the log-likelihood
    estimate, the method that ran, whether Ctrl-C stopped it, and the warnings.
    ``bse``: standard errors by name where the method gives them (the robust particle
    EM fit and the direct fit, from the curvature of an accurate filter's
    log-likelihood at the estimate, when it is a maximum's), else ``None``."""

    def __init__(self, raw, origin="<fit>"):
        self._raw = dict(raw)
        self.model = ModelFile.from_string(raw["text"], origin)
        self.method = raw["method"]
        self.param_names = list(raw["names"])
        self.llf = raw["loglik"]
        self.interrupted = raw["interrupted"]
        self.warnings = list(raw["warnings"])

    @property
    def loglik(self):
        return self.llf

    @property
    def params(self):
        return dict(zip(self.param_names, self._raw["estimate"]))

    @property
    def bse(self):
        se = self._raw.get("standard_errors")
        return None if se is None else dict(zip(self.param_names, se))

    def __reduce__(self):
        return (ModelFitResults, (self._raw, self.model.origin))

    def __repr__(self):
        return (f"<ModelFitResults method={self.method} params={self.params} llf={self.llf} "
                f"interrupted={self.interrupted} warnings={len(self.warnings)}>")

    def __eq__(self, other):
        return isinstance(other, ModelFitResults) and _same(self._raw, other._raw)


class SimulationComparison:
    """A model file's noise-free simulation of a record: ``outputs`` ``(T, p)``,
    ``rms`` and ``fit_percent`` by output name, ``initial_state``."""

    def __init__(self, raw, names):
        self.outputs = np.asarray(raw["outputs"])
        self.initial_state = list(raw["initial_state"])
        self.rms = dict(zip(names, raw["rms"]))
        self.fit_percent = dict(zip(names, raw["fit_percent"]))

    def __repr__(self):
        return f"<SimulationComparison rms={self.rms} fit_percent={self.fit_percent}>"


class SimulationFitResults:
    """``sysid fit --model --criterion simulation``: the fitted model file (the estimated
    initial state as its initial means), ``params``, ``bse`` (standard errors),
    ``initial_state``, ``rms`` and ``fit_percent`` on the estimation record, every
    Levenberg-Marquardt run (``runs``: rms, evaluations, termination, converged), and
    the warnings (inseparable parameters, a bound reached, no convergence)."""

    def __init__(self, raw, origin="<fit>"):
        self._raw = dict(raw)
        self.model = ModelFile.from_string(raw["text"], origin)
        self.param_names = list(raw["names"])
        self.initial_state = list(raw["initial_state"])
        outputs = self.model.outputs
        self.rms = dict(zip(outputs, raw["rms"]))
        self.fit_percent = dict(zip(outputs, raw["fit_percent"]))
        self.runs = [dict(zip(("rms", "evaluations", "termination", "converged"), r))
                     for r in raw["runs"]]
        self.best = raw["best"]
        self.interrupted = raw["interrupted"]
        self.warnings = list(raw["warnings"])

    @property
    def params(self):
        return dict(zip(self.param_names, self._raw["estimate"]))

    @property
    def bse(self):
        return dict(zip(self.param_names, self._raw["standard_errors"]))

    def __reduce__(self):
        return (SimulationFitResults, (self._raw, self.model.origin))

    def __repr__(self):
        return (f"<SimulationFitResults params={self.params} rms={self.rms} "
                f"interrupted={self.interrupted} warnings={len(self.warnings)}>")

    def __eq__(self, other):
        return isinstance(other, SimulationFitResults) and _same(self._raw, other._raw)


def fit_defaults():
    """The default of every keyword of ``fit`` that is ``None`` in its signature: the
    library's, as ``sysid fit --help`` shows them (a dict)."""
    return dict(_sysid.fit_defaults())


def fit(model, data, u=None, *, criterion="likelihood", method=None, particles=None,
        smoother=None, max_iter=None, starts=None, seed=1, spread=None, patience=None,
        time=None, progress=None, threads=None, strict=False, polish=None,
        extrapolate=None):
    """``sysid fit --model``. ``criterion="likelihood"`` (the default): maximum
    likelihood for a model file's free parameters, by the method the command line
    chooses: closed-form particle EM when the equations are affine in them (``method``
    ``robust``, ``em`` or ``psaem``); otherwise ``robust`` maximises the particle
    likelihood directly from ``starts`` starts (the file's values, the simulation-error
    fit's estimate, perturbations; ``method`` of the result ``"direct"``) and ``em`` is
    gradient EM from the file's values. ``criterion="simulation"``:
    the noise-free model's simulation error minimised over the free parameters and the
    initial state (Levenberg-Marquardt from the file's values and ``starts - 1``
    perturbations, each value times ``exp(spread N(0, 1))``); returns
    ``SimulationFitResults``.

    A keyword left ``None`` takes the default of the method that runs: the library's,
    which ``sysid.fit_defaults()`` returns and ``sysid fit --help`` shows. A keyword
    the method does not read raises ``OptionError``
    naming the method: ``particles`` for the direct search, ``starts`` for ``em``,
    ``max_iter`` for ``criterion="simulation"``. ``polish`` (robust method and the
    direct search): finish by maximising a 10 000-particle likelihood directly.
    ``extrapolate`` (robust particle EM): the refinement jumps along its own drift
    every 25 iterations, a jump kept only when the ranking filter gains a nat."""
    model = _model(model)
    s = model._signals(data, u, time)
    result = SimulationFitResults if criterion == "simulation" else ModelFitResults
    with partial_as(lambda raw: result(raw, model.origin)):
        raw = _sysid.fit_model(model._compiled, s.y, s.u, criterion, method, particles,
                               smoother, max_iter, starts,
                               None if polish is None else bool(polish),
                               None if extrapolate is None else bool(extrapolate),
                               patience, spread, seed, progress, threads)
    return report(result(raw, model.origin), strict, "fit")


class Chains:
    """MCMC chains (``sysid pmmh --out`` writes the same JSON): ``draws`` (chains x
    kept iterations x parameters), ``summary()``, ``acceptance``, ``warnings``."""

    def __init__(self, chains, ids):
        self._chains = chains if isinstance(chains, list) else json.loads(chains)
        self.ids = list(ids)
        report_ = _sysid.chain_report(json.dumps(self._chains))
        self._summary = json.loads(report_["summary"])
        self.acceptance = list(report_["acceptance"])
        self.warnings = list(report_["warnings"])
        self.iterations = report_["iterations"]

    @property
    def param_names(self):
        return list(self._chains[0]["names"])

    @property
    def interrupted(self):
        return any(c["interrupted"] for c in self._chains)

    @property
    def draws(self):
        """The draws after burn-in: an array (chains, iterations, parameters)."""
        d = len(self.param_names)
        kept = [np.asarray(c["samples"], dtype=float).reshape(-1, d)[c["burn_in"]:]
                for c in self._chains]
        n = min(len(k) for k in kept)
        return np.stack([k[:n] for k in kept])

    def to_json(self):
        """The chains as ``sysid pmmh --out`` writes them."""
        return json.dumps({"chains": self._chains})

    def summary(self):
        """Mean, sd, MCSE, ESS (bulk, tail), R-hat and quantiles of every parameter (a
        DataFrame with pandas, else a list of dicts)."""
        try:
            import pandas as pd
        except ImportError:
            return self._summary
        return pd.DataFrame(self._summary).set_index("name")

    @staticmethod
    def concat(parts):
        """Chains run apart (``pmmh(chains=[0, 1])``, ``pmmh(chains=[2, 3])``) as one
        run's: equal to ``pmmh(chains=4)``."""
        pairs = sorted((i, c) for p in parts for i, c in zip(p.ids, p._chains))
        ids = [i for i, _ in pairs]
        if len(set(ids)) != len(ids):
            raise OptionError("Chains.concat: a chain appears twice", "parts")
        return Chains([c for _, c in pairs], ids)

    def __reduce__(self):
        return (Chains, (self._chains, self.ids))

    def __repr__(self):
        return (f"<Chains ids={self.ids} params={self.param_names} "
                f"iterations={self.iterations} warnings={len(self.warnings)}>")

    def __eq__(self, other):
        return isinstance(other, Chains) and self.ids == other.ids and _same(
            self._chains, other._chains)


def _blocks(ids):
    """Consecutive runs of chain ids: ``[0, 1, 3]`` -> ``[(0, 2), (3, 1)]``."""
    blocks = []
    for i in ids:
        if blocks and blocks[-1][0] + blocks[-1][1] == i:
            blocks[-1] = (blocks[-1][0], blocks[-1][1] + 1)
        else:
            blocks.append((i, 1))
    return blocks


def pmmh(model, data, u=None, *, chains=4, iterations=10000, burn_in=None, particles=100,
         seed=1, proposal_sd=None, adapt=True, time=None, progress=None, threads=None,
         strict=False):
    """``sysid pmmh --model``: particle marginal Metropolis-Hastings over the model
    file's free parameters (priors from the file). ``chains`` is a number or a list of
    chain ids (chain ``c`` draws from the stream ``(seed, c)`` wherever it runs), so
    that chains spread over workers concatenate (``Chains.concat``) to one run's."""
    model = _model(model)
    s = model._signals(data, u, time)
    ids = list(range(chains)) if isinstance(chains, int) else sorted(int(c) for c in chains)
    if not ids or len(set(ids)) != len(ids) or ids[0] < 0:
        raise OptionError(f"chains: {chains!r} is not a number or a list of distinct ids",
                          "chains")
    drawn, done = [], []

    def so_far(raw, first, count):
        """The chains of the blocks before and of the one stopped (Ctrl-C)."""
        return Chains(drawn + json.loads(raw["chains"]), done + list(range(first, first + count)))

    for first, count in _blocks(ids):
        with partial_as(lambda raw, first=first, count=count: so_far(raw, first, count)):
            raw = _sysid.pmmh_model(model._compiled, s.y, s.u, count, first, iterations,
                                    burn_in, particles, seed, proposal_sd, adapt, progress,
                                    threads)
        drawn += json.loads(raw["chains"])
        done += list(range(first, first + count))
    return report(Chains(drawn, ids), strict, "pmmh")
