"""Identifier configurations for the paper's examples.

Each preset is read from the config file shipped with the package
(``pyrhonn/configs/<name>.toml``, format in :mod:`pyrhonn.configfile`), so
the file is the single source: ``pyrhonn show-config example1`` prints the
terms, the tuning and why each neuron uses its terms.

Example 1 (section 6.1.2, eq. 20): bipolar activation of eq. 19 with slope
0.01, P_i(0) = 1e8 I, Q_i = 5e5 I, R_i = 1e4, and four weights per neuron
("diag(4)"). The paper does not list the four terms; these are chosen from
the structure of eq. 15: each neuron sees its own state, its product with
its chain partner (x1-x2, x3-x4, the van der Pol pairs), the one-sample
delayed x1 (the delayed coupling of eq. 15, which the identifier is not told
the delay of) and the input.
"""
from __future__ import annotations

from .config import IdentifierConfig

__all__ = ["example1"]


def example1(dtype: str = "float64") -> IdentifierConfig:
    """The Example 1 identifier with the paper's eq. 20 tuning (``configs/example1.toml``)."""
    from .configfile import load_shipped

    config = load_shipped("example1").config
    return config if config.dtype == dtype else config.replace(dtype=dtype)
