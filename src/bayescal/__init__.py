"""bayescal: Bayesian calibration of dynamic building-simulation models.

Kennedy-O'Hagan calibration with the Higdon et al. PCA basis, as in
"Coupling stochastic methods and detailed dynamic simulation programs for
model calibration: two preliminary case studies".
"""

from bayescal.errors import BayescalError, ConfigError, DataError, SimulatorError

__version__ = "0.1.0"

__all__ = ["BayescalError", "ConfigError", "DataError", "SimulatorError", "__version__"]
