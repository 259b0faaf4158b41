"""sysid: identification of dynamic systems from data, in Rust.

Maximum likelihood by EM for linear Gaussian state-space models (``fit_lti``), subspace
identification (``n4sid``), particle filters, particle EM and PMMH for your own
nonlinear model written as a model file (``ModelFile``, ``particle_filter``, ``fit``,
``pmmh``). Every function gives the numbers of the ``sysid`` command of the same name
for the same data, options and seed; computations release the GIL, stop at Ctrl-C
(with the partial result on the exception as ``.partial``), take ``threads=`` (results
do not depend on it) and ``progress=True`` or a callable ``(done, total)``.
"""

from ._errors import (DataError, ModelFileError, OptionError, SysidError, SysidWarning,
                      UntrustedResultError)
from ._linear import (Comparison, Forecast, LinearFitResults, LinearModel, N4sidResults,
                      Predictions, ResidualTests, fit_lti, loglik, n4sid)
from ._particle import (Chains, FilterResults, ModelFile, ModelFitResults,
                        SimulationComparison, SimulationFitResults, fit, fit_defaults,
                        particle_filter, pmmh)
from ._sysid import __version__

__all__ = [
    "Chains", "Comparison", "DataError", "Forecast", "Predictions", "ResidualTests", "FilterResults", "LinearFitResults", "LinearModel",
    "ModelFile", "ModelFileError", "ModelFitResults", "N4sidResults", "OptionError",
    "SimulationComparison", "SimulationFitResults",
    "SysidError", "SysidWarning", "UntrustedResultError", "__version__", "fit", "fit_defaults", "fit_lti",
    "loglik", "n4sid", "particle_filter", "pmmh",
]
