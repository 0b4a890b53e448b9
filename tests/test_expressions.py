"""Derived-quantity expressions: safe parsing and vectorised evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.errors import ConfigError
from bayescal.expressions import Expression


def test_arithmetic_of_parameters_on_arrays() -> None:
    expr = Expression.parse("0.3 / k_brick + 0.08 / k_eps", ["k_brick", "k_eps", "c"])
    assert expr.names == ("k_brick", "k_eps")
    k = np.array([0.2, 0.25])
    np.testing.assert_allclose(expr.evaluate({"k_brick": k, "k_eps": 0.04}), 0.3 / k + 2.0)
    ok = Expression.parse("-log(a) ** 2 + sqrt(abs(b)) * exp(0) - log10(100)", ["a", "b"])
    assert float(ok.evaluate({"a": np.e, "b": -4.0})) == pytest.approx(-1.0 + 2.0 - 2.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("k + z", "unknown name 'z'"),
        ("__import__('os').system('ls')", "Attribute not allowed|only log"),
        ("k.real", "Attribute not allowed"),
        ("open('x')", "only log, log10, exp, sqrt and abs"),
        ("k if k else 1", "IfExp not allowed"),
        ("k[0]", "Subscript not allowed"),
        ("'a' + k", "is not a number"),
        ("k % 2", "Mod not allowed"),
        ("log(k, 2)", "takes one argument"),
        ("k +", "is not an expression"),
    ],
)
def test_anything_but_arithmetic_is_refused(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        Expression.parse(text, ["k"], "derived.x")
