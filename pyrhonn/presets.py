"""Identifier configurations for the paper's examples.

Example 1 (section 6.1.2, eq. 20): bipolar activation of eq. 19 with slope
0.01, P_i(0) = 1e8 I, Q_i = 5e5 I, R_i = 1e4, and four weights per neuron
("diag(4)"). The paper does not list the four terms; these are chosen from
the structure of eq. 15: each neuron sees its own state, its product with
its chain partner (x1-x2, x3-x4, the van der Pol pairs), the one-sample
delayed x1 (the delayed coupling of eq. 15, which the identifier is not told
the delay of) and the input.
"""
from __future__ import annotations

from .config import Activation, Factor, IdentifierConfig

__all__ = ["example1"]


def example1(dtype: str = "float64") -> IdentifierConfig:
    """The Example 1 identifier with the paper's eq. 20 tuning."""
    per = []
    for i in range(4):
        partner = i ^ 1
        per.append(((Factor.s(i),), (Factor.s(i), Factor.s(partner)), (Factor.s(0, delay=1),), (Factor.u(0),)))
    return IdentifierConfig.uniform(per, n_states=4, n_inputs=1, dtype=dtype, activation=Activation.BIPOLAR,
                                    beta=0.01, p0=1e8, q=5e5, r=1e4)
