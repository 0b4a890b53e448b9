"""Arithmetic expressions of named quantities, parsed safely (no ``eval``).

A study may declare derived quantities of its parameters, e.g. the wall's
resistance ``"0.3 / k_brick + 0.08 / k_eps"``. :class:`Expression` parses the
text into Python's syntax tree and accepts only numbers, the declared names,
``+ - * / **``, unary minus and the functions ``log``, ``log10``, ``exp``,
``sqrt`` and ``abs``; anything else (attributes, subscripts, other calls,
comparisons) is refused with a one-line message. Evaluation works on numpy
arrays, so a posterior's draws are transformed all at once.
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError

__all__ = ["FUNCTIONS", "Expression"]

FUNCTIONS: dict[str, Callable[[NDArray[np.float64]], NDArray[np.float64]]] = {
    "log": np.log,
    "log10": np.log10,
    "exp": np.exp,
    "sqrt": np.sqrt,
    "abs": np.abs,
}
_BINARY: dict[type[ast.operator], Callable[[ArrayLike, ArrayLike], ArrayLike]] = {
    ast.Add: np.add,
    ast.Sub: np.subtract,
    ast.Mult: np.multiply,
    ast.Div: np.divide,
    ast.Pow: np.power,
}


@dataclass(frozen=True)
class Expression:
    """A parsed expression of the quantities ``names``.

    Build with :meth:`parse`; evaluate with :meth:`evaluate`.
    """

    text: str
    names: tuple[str, ...]
    tree: ast.Expression

    @classmethod
    def parse(cls, text: str, names: Sequence[str], what: str = "expression") -> Expression:
        """Parse ``text``, allowing only the names ``names`` (see the module docstring).

        Raises
        ------
        ConfigError
            For a syntax error, an unknown name or a construct that is not allowed.
        """
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except SyntaxError as exc:
            raise ConfigError(f"{what}: {text!r} is not an expression ({exc.msg})") from None
        used: list[str] = []
        for node in ast.walk(tree):
            problem = _check(node, names, used)
            if problem:
                raise ConfigError(
                    f"{what}: {text!r}: {problem}",
                    hint="use numbers, parameter names, + - * / **, and log, exp, sqrt, abs",
                )
        return cls(text, tuple(dict.fromkeys(used)), tree)

    def evaluate(self, values: Mapping[str, ArrayLike]) -> NDArray[np.float64]:
        """The expression at ``values`` (name -> number or array; arrays broadcast)."""
        with np.errstate(all="ignore"):
            out = _eval(self.tree.body, values)
        return np.asarray(out, dtype=float)


def _check(node: ast.AST, names: Sequence[str], used: list[str]) -> str | None:
    allowed = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Name, ast.Call, ast.Load)
    if isinstance(node, ast.operator):
        return None if type(node) in _BINARY else f"operator {type(node).__name__} not allowed"
    if isinstance(node, ast.unaryop):
        return None if isinstance(node, ast.USub | ast.UAdd) else "only unary + and - allowed"
    if not isinstance(node, allowed):
        return f"{type(node).__name__} not allowed"
    if isinstance(node, ast.Constant) and not isinstance(node.value, int | float):
        return f"constant {node.value!r} is not a number"
    if isinstance(node, ast.Call):
        fn = node.func
        if not (isinstance(fn, ast.Name) and fn.id in FUNCTIONS) or node.keywords:
            return "only log, log10, exp, sqrt and abs may be called"
        if len(node.args) != 1:
            return f"{fn.id} takes one argument"
    if isinstance(node, ast.Name) and node.id not in FUNCTIONS:
        if node.id not in names:
            return f"unknown name {node.id!r} (known: {', '.join(names)})"
        used.append(node.id)
    return None


def _eval(node: ast.expr, values: Mapping[str, ArrayLike]) -> ArrayLike:
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
        return float(node.value)
    if isinstance(node, ast.Name):
        return np.asarray(values[node.id], dtype=float)
    if isinstance(node, ast.UnaryOp):
        inner = _eval(node.operand, values)
        return np.negative(inner) if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_eval(node.left, values), _eval(node.right, values))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        return FUNCTIONS[node.func.id](np.asarray(_eval(node.args[0], values), dtype=float))
    raise ConfigError(f"cannot evaluate {ast.dump(node)}")  # pragma: no cover - parse refuses
