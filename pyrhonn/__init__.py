"""pyrhonn: a real-time RHONN identifier trained by a per-neuron EKF.

See README.md for the quick start and ``csrc/include/rhonn.h`` for the C core;
docs/development.md for working on it from a clone.
"""
from __future__ import annotations

from . import compiled

compiled.require(__name__)  # a clear ImportError in a source tree that was never built (docs/development.md)

from .config import Activation, CovarianceForm, Factor, FactorKind, IdentifierConfig, NeuronConfig, Term
from . import presets, terms, version
from .identifier import Identifier, IdentifierError, NeuronHealth, capacities

__version__ = version.__version__

__all__ = [
    "Activation",
    "CovarianceForm",
    "Factor",
    "FactorKind",
    "Identifier",
    "IdentifierConfig",
    "IdentifierError",
    "NeuronHealth",
    "capacities",
    "presets",
    "NeuronConfig",
    "Term",
    "terms",
]
