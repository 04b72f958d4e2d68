"""``--filter`` expressions: a small comparison language, parsed once, evaluated per block.

Grammar (Python's expression syntax, of which only these forms are accepted)::

    expr    := expr "or" expr | expr "and" expr | "not" expr | "(" expr ")" | compare
    compare := value (("<" | "<=" | ">" | ">=" | "==" | "!=") value)+     (chains: 0.1 < opacity < 0.5)
    value   := number | attribute | value ("+" | "-" | "*" | "/") value | "-" value
             | ("abs" | "min" | "max" | "sqrt" | "log") "(" value ("," value)* ")"

The text is parsed with :func:`ast.parse` and every node is checked against this whitelist
before anything runs; nothing is ever handed to ``eval``, no name other than the attributes of
:mod:`splatgl.edit.attributes` and the five functions resolves, and no attribute access,
subscript, call of anything else, string or keyword is accepted.  Evaluation walks the checked
tree with NumPy over a block of rows (:class:`~splatgl.edit.attributes.Rows`).  Errors are one
:class:`SplatglError` line quoting the expression and saying what is wrong and where.
"""

from __future__ import annotations

import ast
import difflib
import operator
from dataclasses import dataclass, field

import numpy as np

from ..errors import SplatglError
from .attributes import ATTRIBUTES, Rows

#: Longest expression accepted (characters): a comparison language needs no more, and it bounds
#: the parser's work on hostile input.
MAX_LENGTH = 1000
#: Deepest nesting accepted.
MAX_DEPTH = 32

_COMPARE = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt,
            ast.GtE: operator.ge, ast.Eq: operator.eq, ast.NotEq: operator.ne}
_ARITH = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
          ast.Div: operator.truediv}
_FUNCTIONS = {"abs": (np.abs, 1, 1), "sqrt": (np.sqrt, 1, 1), "log": (np.log, 1, 1),
              "min": (np.minimum.reduce, 2, 8), "max": (np.maximum.reduce, 2, 8)}
#: Operator spellings from other languages and what to write instead.
_HINTS = (("&&", "and"), ("||", "or"), ("!(", "not ("), ("=<", "<="), ("=>", ">="))


@dataclass(frozen=True)
class Expression:
    """A checked filter expression: ``text`` as given and the attributes it reads."""

    text: str
    tree: ast.expr = field(repr=False, compare=False)
    names: frozenset[str] = frozenset()

    def evaluate(self, rows: Rows) -> np.ndarray:
        """(M,) bool: where the expression holds on ``rows`` (NaN compares false)."""
        with np.errstate(all="ignore"):
            out = _eval(self.tree, rows)
        return np.broadcast_to(np.asarray(out, bool), (rows.stop - rows.start,))


def parse_expression(text: str, what: str = "--filter") -> Expression:
    """Check ``text`` against the grammar above; :class:`SplatglError` (one line) otherwise."""
    def fail(reason: str) -> SplatglError:
        return SplatglError(f"{what} {text!r}: {reason}")

    if not isinstance(text, str) or not text.strip():
        raise fail("empty expression (example: 'opacity < 0.02 or max_scale > 0.5')")
    if len(text) > MAX_LENGTH:
        raise fail(f"longer than {MAX_LENGTH} characters")
    for wrong, right in _HINTS:
        if wrong in text:
            raise fail(f"'{wrong}' is not an operator here; write '{right}'")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except SyntaxError as exc:
        hint = " (compare with '==', not '=')" if "=" in text and "==" not in text else ""
        said = f": {exc.msg}" if exc.msg and exc.msg != "invalid syntax" else ""
        raise fail(f"syntax error at {_column(text, exc)}{said}{hint}") from None
    except (ValueError, RecursionError, MemoryError):
        raise fail("cannot be parsed") from None
    names: set[str] = set()
    kind = _check(tree, fail, names, 0)
    if kind != "bool":
        raise fail("is a value, not a condition (compare it, e.g. 'opacity < 0.02')")
    return Expression(text, tree, frozenset(names))


def _column(text: str, exc: SyntaxError) -> str:
    """Where ``exc`` points in ``text`` (columns from 1; the parser saw ``text.strip()``, and
    gives no column when the expression stops short)."""
    lead = len(text) - len(text.lstrip())
    line = text.strip().splitlines()[(exc.lineno or 1) - 1] if text.strip() else ""
    if not exc.offset or exc.offset > len(line):
        return f"column {lead + len(text.strip()) + 1} (the expression ends too early)"
    if (exc.lineno or 1) > 1:
        return f"line {exc.lineno} column {exc.offset}"
    return f"column {lead + exc.offset}"


def _check(node: ast.AST, fail, names: set[str], depth: int) -> str:
    """The node's type, "bool" or "number", after checking it against the whitelist."""
    if depth > MAX_DEPTH:
        raise fail(f"nested deeper than {MAX_DEPTH} levels")
    col = f" at column {getattr(node, 'col_offset', 0) + 1}"
    if isinstance(node, ast.BoolOp):
        for value in node.values:
            if _check(value, fail, names, depth + 1) != "bool":
                raise fail(f"'{'and' if isinstance(node.op, ast.And) else 'or'}' joins "
                           f"conditions, not values{col}")
        return "bool"
    if isinstance(node, ast.UnaryOp):
        inner = _check(node.operand, fail, names, depth + 1)
        if isinstance(node.op, ast.Not):
            if inner != "bool":
                raise fail(f"'not' applies to a condition{col}")
            return "bool"
        if isinstance(node.op, (ast.USub, ast.UAdd)) and inner == "number":
            return "number"
        raise fail(f"unsupported operator{col}")
    if isinstance(node, ast.Compare):
        for op in node.ops:
            if type(op) not in _COMPARE:
                raise fail(f"unsupported comparison{col} (use <, <=, >, >=, ==, !=)")
        for value in [node.left, *node.comparators]:
            if _check(value, fail, names, depth + 1) != "number":
                raise fail(f"a comparison compares values, not conditions{col}")
        return "bool"
    if isinstance(node, ast.BinOp):
        if type(node.op) not in _ARITH:
            raise fail(f"unsupported operator{col} (use +, -, *, /)")
        for value in (node.left, node.right):
            if _check(value, fail, names, depth + 1) != "number":
                raise fail(f"arithmetic on a condition{col}")
        return "number"
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise fail(f"only numbers are allowed as constants{col}, got {node.value!r}")
        return "number"
    if isinstance(node, ast.Name):
        if node.id not in ATTRIBUTES:
            close = difflib.get_close_matches(node.id, [*ATTRIBUTES, *_FUNCTIONS], n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise fail(f"unknown attribute '{node.id}'{hint}; known: {', '.join(ATTRIBUTES)}")
        names.add(node.id)
        return "number"
    if isinstance(node, ast.Call):
        fn = node.func.id if isinstance(node.func, ast.Name) else None
        if fn not in _FUNCTIONS or node.keywords:
            raise fail(f"unsupported call{col} (functions: {', '.join(_FUNCTIONS)})")
        _, lo, hi = _FUNCTIONS[fn]
        if not lo <= len(node.args) <= hi:
            raise fail(f"{fn}() takes {lo if lo == hi else f'{lo}-{hi}'} argument(s){col}")
        for arg in node.args:
            if _check(arg, fail, names, depth + 1) != "number":
                raise fail(f"{fn}() takes values, not conditions{col}")
        return "number"
    raise fail(f"'{ast.unparse(node)}' is not allowed{col} (comparisons of attributes and "
               "numbers, joined by and/or/not)")


def _eval(node: ast.AST, rows: Rows):
    """Evaluate a checked node over ``rows`` (arrays or scalars)."""
    if isinstance(node, ast.BoolOp):
        parts = [np.asarray(_eval(v, rows), bool) for v in node.values]
        join = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
        return join.reduce(np.broadcast_arrays(*parts)) if len(parts) > 1 else parts[0]
    if isinstance(node, ast.UnaryOp):
        value = _eval(node.operand, rows)
        if isinstance(node.op, ast.Not):
            return np.logical_not(value)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Compare):
        left = _eval(node.left, rows)
        result = True
        for op, comp in zip(node.ops, node.comparators):
            right = _eval(comp, rows)
            result = np.logical_and(result, _COMPARE[type(op)](left, right))
            left = right
        return result
    if isinstance(node, ast.BinOp):
        return _ARITH[type(node.op)](_eval(node.left, rows), _eval(node.right, rows))
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return _attribute(rows, node.id)
    if isinstance(node, ast.Call):
        fn, lo, _ = _FUNCTIONS[node.func.id]
        args = [_eval(a, rows) for a in node.args]
        return fn(args[0]) if lo == 1 else fn(np.broadcast_arrays(*args))
    raise AssertionError(f"unchecked node {node!r}")  # _check admits nothing else


def _attribute(rows: Rows, name: str) -> np.ndarray:
    cache = rows.__dict__.setdefault("_attributes", {})
    if name not in cache:
        cache[name] = ATTRIBUTES[name].compute(rows)
    return cache[name]
