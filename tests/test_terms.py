"""Term builders of pyrhonn.terms that the other tests do not exercise:
an input acting after a dead time."""
from __future__ import annotations

import numpy as np
import pytest

from pyrhonn import Factor, Identifier, IdentifierConfig, NeuronConfig, terms


def test_delayed_inputs_build_one_term_per_dead_time() -> None:
    assert terms.delayed_inputs(0, [3]) == ((Factor.u(0, delay=3),),)
    built = terms.delayed_inputs(1, [0, 2], power=2)
    assert built == ((Factor.u(1, 2),), (Factor.u(1, 2, delay=2),))
    assert [str(t[0]) for t in built] == ["u2^2", "u2(k-2)^2"]


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_an_identifier_with_a_delayed_input_reads_the_input_three_steps_back(dtype: str) -> None:
    nr = NeuronConfig(terms=terms.delayed_inputs(0, [3]), w0=np.array([2.0]))
    ident = Identifier(IdentifierConfig(n_states=1, n_inputs=1, neurons=(nr,), dtype=dtype))
    ident.learning = False
    u = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], dtype=dtype)
    out = [float(ident.step(np.zeros(1, dtype=dtype), u[k:k + 1])[0]) for k in range(len(u))]
    assert out[3:] == [2.0 * float(u[k - 3]) for k in range(3, len(u))]


@pytest.mark.parametrize(("kwargs", "field"), [({"input_index": -1, "delays": [1]}, "input_index"),
                                               ({"input_index": 0, "delays": [1, -2]}, "delays"),
                                               ({"input_index": 0, "delays": [1], "power": 0}, "power"),
                                               ({"input_index": True, "delays": [1]}, "input_index")])
def test_delayed_inputs_refuse_bad_arguments_naming_them(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}:"):
        terms.delayed_inputs(**kwargs)
