"""Linear Gaussian state-space models: ``loglik``, ``n4sid``, ``fit_lti`` and the
model files they read and write (the command line's JSON)."""

import json
import math
import os
from statistics import NormalDist

import numpy as np

from . import _sysid
from ._data import signals
from ._errors import OptionError, SysidError
from ._trust import partial_as, report


def _write_new(path, text, overwrite):
    """Writes ``text`` to ``path``; an existing file only with ``overwrite``."""
    path = os.fspath(path)
    mode = "w" if overwrite else "x"
    try:
        with open(path, mode, encoding="utf-8") as f:
            f.write(text)
    except FileExistsError:
        raise SysidError(f"{path} exists: pass overwrite=True to replace it") from None


class LinearModel:
    """A linear Gaussian state-space model as a model file of the command line
    (``sysid fit lti --out m.json`` writes one; every command reads one)."""

    def __init__(self, text):
        self._text = text if isinstance(text, str) else json.dumps(text)
        self._spec = json.loads(self._text)

    @classmethod
    def load(cls, path):
        with open(os.fspath(path), encoding="utf-8") as f:
            return cls(f.read())

    def to_json(self):
        """The model file's text."""
        return self._text

    def save(self, path, overwrite=False):
        """Writes the model file (refuses to replace a file unless ``overwrite``)."""
        _write_new(path, self._text, overwrite)

    @property
    def order(self):
        return len(self._spec["a"])

    def matrix(self, name):
        """A matrix of the model (``A``, ``B``, ``C``, ``D``, ``Q``, ``R``, ``S``, ``h``,
        ``mu``, ``P1``), as a numpy array."""
        key = name.lower()
        if key not in self._spec:
            raise KeyError(f"{name}: not in the model (it has {sorted(self._spec)})")
        return np.array(self._spec[key], dtype=float)

    @property
    def metadata(self):
        return dict(self._spec.get("metadata") or {})

    def loglik(self, data, u=None, *, time=None, initial="model"):
        """``sysid loglik``: the exact log-likelihood of a record."""
        s = signals(data, u, time, model_names=self._names())
        return _sysid.loglik(self._text, s.y, s.u, s.time, initial)

    def compare(self, data, u=None, *, horizon="inf", burn_in=0, time=None, initial="model"):
        """``sysid compare``: the simulated (``horizon="inf"``) or ``horizon``-step
        predicted outputs and the fit per output in percent (MATLAB's ``compare``)."""
        s = signals(data, u, time, model_names=self._names())
        raw = _sysid.compare(self._text, s.y, s.u, s.time, str(horizon), burn_in, initial)
        return Comparison(raw, s.outputs)

    def predict(self, data, u=None, *, horizon=1, time=None, initial="model", strict=False):
        """``sysid predict``: ``horizon``-step predictions with their sd, the errors and
        the standardised errors (``Predictions``)."""
        s = signals(data, u, time, model_names=self._names())
        raw = _sysid.predict(self._text, s.y, s.u, s.time, horizon, initial)
        return report(Predictions(raw, s.outputs), strict, "predict")

    def forecast(self, data, u=None, *, steps=10, future_u=None, alpha=0.05, time=None,
                 initial="model"):
        """``sysid forecast``: the outputs ``steps`` past the record with ``1 - alpha``
        intervals; a model with inputs needs their future values ``future_u``
        ``(steps, m)``."""
        s = signals(data, u, time, model_names=self._names())
        if future_u is not None:
            future_u = np.asarray(future_u, dtype=np.float64)
            future_u = future_u[:, None] if future_u.ndim == 1 else future_u
        raw = _sysid.forecast(self._text, s.y, s.u, s.time, future_u, steps, 1 - alpha,
                              initial)
        return Forecast(raw, s.outputs)

    def resid(self, data, u=None, *, lags=20, time=None, initial="model", strict=False):
        """``sysid resid``: are the one-step prediction errors white (autocorrelations,
        Ljung-Box) and independent of the inputs (cross-correlations)?"""
        s = signals(data, u, time, model_names=self._names())
        raw = _sysid.resid(self._text, s.y, s.u, s.time, lags, initial, s.outputs, s.inputs)
        return report(ResidualTests(raw), strict, "resid")

    def _names(self):
        m = self.metadata
        return (m.get("inputs", []), m.get("outputs", []))

    def __eq__(self, other):
        return isinstance(other, LinearModel) and self._text == other._text

    def __repr__(self):
        return f"LinearModel(order={self.order})"


def _frame(values, names, index=None):
    """A (T, p) array as a DataFrame with pandas, else the array."""
    try:
        import pandas as pd
    except ImportError:
        return np.asarray(values)
    return pd.DataFrame(np.asarray(values), columns=names, index=index)


class _Plain:
    """Results compared by their raw numbers (NaN equal to NaN)."""

    def __eq__(self, other):
        return type(other) is type(self) and _same(_plain(self._raw), _plain(other._raw))


def _plain(raw):
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in raw.items()}


class Comparison(_Plain):
    """``sysid compare``: ``outputs`` (simulated or predicted) and ``fit_percent``."""

    def __init__(self, raw, names):
        self._raw, self.names = raw, list(names)
        self.outputs = _frame(raw["outputs"], self.names)
        self.fit_percent = dict(zip(self.names, raw["fit_percent"]))
        self.fit_percent_mean = raw["fit_percent_mean"]


class Predictions(_Plain):
    """``sysid predict``: ``mean``, ``sd``, ``errors``, ``standardised``, ``fit_percent``,
    ``standardised_rms`` and ``warnings``."""

    def __init__(self, raw, names):
        self._raw, self.names = raw, list(names)
        for key in ("mean", "sd", "errors", "standardised"):
            setattr(self, key, _frame(raw[key], self.names))
        self.loglik = raw["loglik"]
        self.fit_percent = dict(zip(self.names, raw["fit_percent"]))
        self.standardised_rms = dict(zip(self.names, raw["standardised_rms"]))
        self.warnings = list(raw["warnings"])


class Forecast(_Plain):
    """``sysid forecast``: ``mean``, ``sd``, ``lower`` and ``upper`` at the times
    ``time`` after the record."""

    def __init__(self, raw, names):
        self._raw, self.names = raw, list(names)
        self.time = list(raw["time"])
        for key in ("mean", "sd", "lower", "upper"):
            setattr(self, key, _frame(raw[key], self.names, self.time))
        self.z = raw["z"]


class ResidualTests(_Plain):
    """``sysid resid``: per output, the autocorrelations, cross-correlations with the
    inputs and the Ljung-Box test; ``warnings`` when they are not white."""

    def __init__(self, raw):
        self._raw = raw
        self.lags = raw["lags"]
        self.outputs = [dict(o) for o in raw["outputs"]]
        self.warnings = list(raw["warnings"])


def loglik(model, data, u=None, *, time=None, initial="model"):
    """``sysid loglik``: the exact log-likelihood of ``model`` (a ``LinearModel`` or a
    model file's path) on a record."""
    if not isinstance(model, LinearModel):
        model = LinearModel.load(model)
    return model.loglik(data, u, time=time, initial=initial)


class N4sidResults:
    """The subspace model and what ``sysid n4sid`` reports."""

    def __init__(self, raw):
        self.model = LinearModel(raw["model"])
        self.order = raw["order"]
        self.block_rows = raw["block_rows"]
        self.singular_values = np.array(raw["singular_values"])
        self.spectral_radius = raw["spectral_radius"]
        self.stabilised = raw["stabilised"]
        self.weighting = raw["weighting"]
        # weighting="auto": each weighting's order, spectral radius, stability and
        # one-step prediction fit (%) on the data
        self.weightings = [dict(zip(("weighting", "order", "spectral_radius", "stable",
                                     "prediction_fit"), w)) for w in raw["weightings"]]
        self.warnings = list(raw["warnings"])

    def __repr__(self):
        return (f"<N4sidResults order={self.order} spectral_radius={self.spectral_radius:.4g} "
                f"warnings={len(self.warnings)}>")

    def __eq__(self, other):
        return isinstance(other, N4sidResults) and self.__dict__.keys() == other.__dict__.keys() and all(
            np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
            for a, b in zip(self.__dict__.values(), other.__dict__.values()))


def n4sid(data, order="auto", u=None, *, block_rows=None, weighting="auto",
          focus="prediction", criterion="bic", stable=False, detrend=None, time=None,
          strict=False):
    """``sysid n4sid``: a subspace fit (N4SID/MOESP/CVA) of ``order`` states, or the
    order chosen by ``criterion`` (``order="auto"``). ``weighting="auto"`` fits all three
    weightings and keeps the stable model with the best one-step prediction fit
    (``.weightings`` reports them)."""
    s = signals(data, u, time)
    if order == "auto" or order is None:
        order = None
    elif not isinstance(order, int) or isinstance(order, bool) or order < 1:
        raise OptionError(f"order: expected a positive integer or 'auto', got {order!r}", "order")
    raw = _sysid.n4sid(s.y, s.u, order, block_rows, weighting, focus, criterion, stable,
                       detrend, s.time)
    return report(N4sidResults(raw), strict, "n4sid")


class LinearFitResults:
    """A fitted linear model (``sysid fit lti``), in statsmodels' spelling:
    ``params``, ``bse``, ``conf_int()``, ``llf``, ``aic``, ``bic``, ``summary()``."""

    def __init__(self, raw, training=None):
        self._raw = raw
        self._training = training
        self.model = LinearModel(raw["model"])
        self.llf = raw["loglik"]
        self.aic = raw["aic"]
        self.bic = raw["bic"]
        self.nobs = raw["nobs"]
        self.df_model = raw["df_model"]
        self.iterations = raw["iterations"]
        self.e_steps = raw["e_steps"]
        self.termination = raw["termination"]
        self.trace = np.array(raw["trace"], dtype=float)
        self.warnings = list(raw["warnings"])
        self.validation = raw.get("validation")
        self.failure = raw.get("failure")
        rows = raw.get("parameters") or []
        self.param_names = [r[0] for r in rows]
        self._values = np.array([r[1] for r in rows], dtype=float)
        self._errors = np.array([r[2] for r in rows], dtype=float)
        cov = raw.get("covariance")
        self.cov_params_ = None if cov is None else np.array(cov, dtype=float)
        self._table = raw.get("order_table")
        self.order_chosen = raw.get("order_chosen")

    @property
    def loglik(self):
        return self.llf

    def _series(self, values, name):
        try:
            import pandas as pd
        except ImportError:
            return dict(zip(self.param_names, values))
        return pd.Series(values, index=self.param_names, name=name)

    @property
    def params(self):
        """The free parameters' estimates (those with standard errors; empty for a
        black-box model, whose entries are not identifiable: see ``model``)."""
        return self._series(self._values, "params")

    @property
    def bse(self):
        """Standard errors from the observed information."""
        return self._series(self._errors, "bse")

    def conf_int(self, alpha=0.05):
        """Normal confidence intervals ``[lower, upper]`` at level ``1 - alpha``."""
        z = NormalDist().inv_cdf(1 - alpha / 2)
        lower, upper = self._values - z * self._errors, self._values + z * self._errors
        try:
            import pandas as pd
        except ImportError:
            return np.column_stack([lower, upper])
        return pd.DataFrame({"lower": lower, "upper": upper}, index=self.param_names)

    @property
    def table(self):
        """With ``order=range(...)``: every order's log-likelihood, parameters, AIC,
        BIC and validation fit (a DataFrame with pandas, else a list of dicts)."""
        if self._table is None:
            return None
        rows = [dict(order=o, loglik=l, parameters=k, aic=a, bic=b, validation_fit=v)
                for (o, l, k, a, b, v) in self._table]
        try:
            import pandas as pd
        except ImportError:
            return rows
        return pd.DataFrame(rows).set_index("order")

    def compare(self, data, u=None, **options):
        """``model.compare``: simulation (or k-step) fit on a record."""
        return self.model.compare(data, u, **options)

    def predict(self, data, u=None, **options):
        """``model.predict``: k-step predictions on a record."""
        return self.model.predict(data, u, **options)

    def forecast(self, data=None, u=None, **options):
        """``model.forecast``: outputs past the end of ``data``, by default the record
        the model was fitted on (``res.forecast(steps=10, alpha=0.05)``)."""
        if data is None:
            if self._training is None:
                raise OptionError("forecast: give the record to continue", "data")
            s = self._training
            data, u = s.y, s.u
            options.setdefault("time", s.time)
        return self.model.forecast(data, u, **options)

    def resid(self, data, u=None, **options):
        """``model.resid``: residual whiteness tests on a record."""
        return self.model.resid(data, u, **options)

    def summary(self):
        """A text summary, as ``sysid fit lti`` prints it."""
        lines = [
            f"Linear Gaussian state-space model, order {self.model.order}",
            f"log-likelihood {self.llf}   AIC {self.aic}   BIC {self.bic}   "
            f"observations {self.nobs}",
            f"EM: {self.iterations} iterations ({self.e_steps} E-steps), {self.termination}",
        ]
        if self.param_names:
            z = NormalDist().inv_cdf(0.975)
            lines.append(f"{'':12}{'estimate':>14}{'std err':>12}{'[0.025':>14}{'0.975]':>14}")
            for n, v, e in zip(self.param_names, self._values, self._errors):
                lines.append(f"{n:12}{v:14.6g}{e:12.4g}{v - z * e:14.6g}{v + z * e:14.6g}")
        if self.validation:
            lines.append(f"validation: {self.validation}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def __eq__(self, other):
        # (the time a fit took is not part of its result)
        strip = lambda raw: {k: v for k, v in raw.items() if k != "seconds"}  # noqa: E731
        return isinstance(other, LinearFitResults) and _same(strip(self._raw), strip(other._raw))

    def __repr__(self):
        return f"<LinearFitResults order={self.model.order} llf={self.llf}>"


def _same(a, b):
    """Equality of two raw results, NaN equal to NaN."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _fixes(fix):
    """``fix=``: names (``["A", "C"]``), ``NAME=VALUE`` strings as the command line
    takes, or a dict ``{"R": 0.01, "C": [[1, 0]]}``."""
    if isinstance(fix, str):
        fix = [fix]
    items = list(fix.items()) if isinstance(fix, dict) else []
    if not isinstance(fix, dict):
        for entry in fix:
            if "=" in entry:
                name, value = entry.split("=", 1)
                try:
                    items.append((name.strip(), json.loads(value)))
                except ValueError:
                    raise OptionError(f"fix: cannot read {value!r} as a number or a JSON matrix",
                                      "fix") from None
            else:
                items.append((entry.strip(), None))
    out = []
    for name, value in items:
        if value is None:
            out.append(name)
        elif isinstance(value, (int, float)):
            out.append((name, float(value)))
        else:
            rows = np.asarray(value, dtype=float)
            rows = rows[:, None] if rows.ndim == 1 else rows
            out.append((name, rows.tolist()))
    return out


def fit_lti(data, order=None, u=None, *, init="n4sid", fix=(), diag=(), full_r=False,
            stable=False, weighting="auto", offset=False, estimate_initial=False,
            initial="model", accelerate="squarem", polish="auto", std_errors="auto", detrend=None,
            split=None, select="bic", max_iter=500, tol=None, tol_nats=1e-4,
            min_variance=0.0, min_output_noise=0.0, time=None, inputs=None, outputs=None,
            progress=None, threads=None, strict=False):
    """``sysid fit lti``: maximum likelihood by EM (SQUAREM-accelerated, then a BFGS
    polish), from an N4SID start or a model. The options are the command's, spelled
    as keywords; ``order`` is a number or a ``range`` (every order fitted, one chosen by
    ``select``). Returns a ``LinearFitResults``."""
    s = signals(data, u, time, inputs, outputs)
    order_range = None
    if isinstance(order, range):
        if len(order) == 0 or order.step != 1:
            raise OptionError(f"order: {order} is not a range of consecutive orders", "order")
        order_range, order = (order.start, order.stop - 1), None
    elif isinstance(order, (tuple, list)):
        order_range, order = (min(order), max(order)), None
    if isinstance(init, LinearModel):
        init = init.to_json()
    elif init != "n4sid":
        init = LinearModel.load(init).to_json()
    else:
        init = None
    switch = {True: "on", False: "off"}
    options = dict(
        order=order, order_range=order_range, select=select, init=init, stable=stable,
        weighting=weighting, fix=_fixes(fix), diag=[diag] if isinstance(diag, str) else list(diag),
        full_r=full_r, min_variance=float(min_variance),
        min_output_noise=float(min_output_noise), offset=offset,
        estimate_initial=estimate_initial, initial=initial, accelerate=accelerate,
        polish=switch.get(polish, polish), std_errors=switch.get(std_errors, std_errors),
        detrend=detrend, split=split, max_iter=max_iter, tol=tol, tol_nats=float(tol_nats))
    with partial_as(lambda raw: LinearFitResults(raw, s)):
        raw = _sysid.fit_lti(s.y, s.u, s.time, s.inputs, s.outputs, options, progress, threads)
    return report(LinearFitResults(raw, s), strict, "fit_lti")
