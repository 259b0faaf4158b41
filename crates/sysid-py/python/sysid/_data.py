"""Data in: numpy arrays ``(T,)`` or ``(T, k)`` of any layout, or pandas DataFrames
whose columns are named as the command line's (``u1, u2, ..., y1, y2, ...``, an
optional time column ``t``) or as a model file's inputs and outputs."""

import re

import numpy as np

from ._errors import DataError

_INPUT = re.compile(r"^u\d+$")
_OUTPUT = re.compile(r"^y\d+$")


def _is_frame(data):
    return hasattr(data, "columns") and hasattr(data, "to_numpy")


def _matrix(values, what):
    """A float64 ``(T, k)`` array (a view when the values already are one)."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise DataError(f"{what}: not numbers ({e})") from None
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2:
        raise DataError(f"{what}: expected a (T,) or (T, k) array, got shape {array.shape}")
    if array.shape[0] == 0:
        raise DataError(f"{what}: no rows")
    return array


class Signals:
    """Outputs ``y`` ``(T, p)``, inputs ``u`` ``(T, m)`` or None, times and names."""

    def __init__(self, y, u, time, inputs, outputs):
        self.y, self.u, self.time = y, u, time
        self.inputs, self.outputs = inputs, outputs

    def __len__(self):
        return self.y.shape[0]


def signals(data, u=None, time=None, inputs=None, outputs=None, model_names=None,
            require_outputs=True):
    """Reads ``data`` (outputs, or a DataFrame with inputs and outputs) and ``u``.

    ``inputs``/``outputs`` choose a DataFrame's columns; else a model file's names
    (``model_names = (inputs, outputs)``) when the frame has them all, else the columns
    ``u1, u2, ...`` and ``y1, y2, ...``.
    """
    if _is_frame(data):
        if u is not None:
            raise DataError("give the inputs as columns of the DataFrame, not as u=")
        columns = [str(c) for c in data.columns]
        if inputs is None and outputs is None and model_names is not None:
            m_in, m_out = model_names
            if m_out and all(n in columns for n in list(m_in) + list(m_out)):
                inputs, outputs = list(m_in), list(m_out)
        if inputs is None and outputs is None:
            inputs = [c for c in columns if _INPUT.match(c)]
            outputs = [c for c in columns if _OUTPUT.match(c)]
            if not outputs and require_outputs:
                raise DataError(
                    f"no output column: the columns are {columns}; name them y1, y2, ... "
                    "(inputs u1, u2, ...) or pass outputs=[...] and inputs=[...]")
        inputs, outputs = list(inputs or []), list(outputs or [])
        missing = [n for n in inputs + outputs if n not in columns]
        if missing:
            raise DataError(f"no column {missing[0]!r} (the columns are {columns})")
        if time is None and "t" in columns:
            time = data["t"].to_numpy(dtype=np.float64)
        y = _matrix(data[outputs].to_numpy(dtype=np.float64), "outputs")
        u = _matrix(data[inputs].to_numpy(dtype=np.float64), "inputs") if inputs else None
    else:
        y = _matrix(data, "y")
        u = None if u is None else _matrix(u, "u")
        if u is not None and u.shape[0] != y.shape[0]:
            raise DataError(f"u has {u.shape[0]} rows and y {y.shape[0]}: one row per step")
        if outputs is None:
            outputs = [f"y{i + 1}" for i in range(y.shape[1])]
        if inputs is None:
            inputs = [f"u{i + 1}" for i in range(0 if u is None else u.shape[1])]
        if len(outputs) != y.shape[1] or len(inputs) != (0 if u is None else u.shape[1]):
            raise DataError("the names given do not match the columns of y and u")
    if time is not None:
        time = [float(t) for t in np.asarray(time, dtype=np.float64).ravel()]
        if len(time) != y.shape[0]:
            raise DataError(f"{len(time)} times for {y.shape[0]} rows")
    return Signals(y, u, time, list(inputs), list(outputs))
