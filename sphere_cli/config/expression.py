"""Arithmetic expressions of position (and time) written in case files, such as an initial fluid
velocity `sin(2*pi*x)*cos(2*pi*y)`: a tokenizer and recursive-descent parser that accept numbers,
the named variables, pi, + - * / ^, parentheses, sin, cos and exp, and nothing else (no Python
eval), and a numpy evaluation of the parsed tree on grids of points."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Annotated, NamedTuple, NoReturn

import numpy as np
from pydantic import AfterValidator, Field

MAX_LENGTH = 2000
MAX_DEPTH = 100  # parentheses, function calls, signs and exponents nested in one another
CONSTANTS = {"pi": math.pi}
FUNCTIONS = {"sin": np.sin, "cos": np.cos, "exp": np.exp}
BINARY = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide, "^": np.power}
DIGITS = "0123456789"
NAME_START = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_"
NAME_PART = NAME_START + DIGITS
# quoted whole in messages up to this length, cut beyond (the column still says where)
QUOTED_LENGTH = 80


class ExpressionError(ValueError):
    """An expression that cannot be parsed, or whose value is not finite somewhere."""


class Number(NamedTuple):
    value: float


class Variable(NamedTuple):
    name: str


class Negate(NamedTuple):
    operand: Node


class Binary(NamedTuple):
    operator: str
    left: Node
    right: Node


class Call(NamedTuple):
    function: str
    argument: Node


Node = Number | Variable | Negate | Binary | Call


def _children(node: Node) -> tuple[Node, ...]:
    if isinstance(node, Binary):
        return (node.left, node.right)
    if isinstance(node, Negate):
        return (node.operand,)
    if isinstance(node, Call):
        return (node.argument,)
    return ()


def _postorder(root: Node) -> Iterator[Node]:
    """Every node after its operands, left before right. A loop, not recursion: "1+1+...+1"
    nests as deep as it is long, past Python's recursion limit."""
    pending = [(root, False)]
    while pending:
        node, operands_done = pending.pop()
        children = _children(node)
        if operands_done or not children:
            yield node
        else:
            pending.append((node, True))
            pending.extend((child, False) for child in reversed(children))


def _quoted(text: str) -> str:
    if len(text) > QUOTED_LENGTH:
        return f'"{text[: QUOTED_LENGTH - 3]}..." ({len(text)} characters)'
    return f'"{text}"'


class _Token(NamedTuple):
    kind: str  # "number", "name", "symbol" (an operator or a parenthesis) or "end"
    text: str
    position: int  # index of the first character


def _tokens(text: str) -> Iterator[_Token]:
    """The tokens of text in order, ending with an "end" token; made one at a time so that the
    first error in the text is the one reported."""
    i = 0
    while i < len(text):
        char = text[i]
        if char.isspace():
            i += 1
        elif _is_digit(text, i) or (char == "." and _is_digit(text, i + 1)):
            end = _number_end(text, i)
            yield _Token("number", text[i:end], i)
            i = end
        elif char in NAME_START:
            end = i
            while end < len(text) and text[end] in NAME_PART:
                end += 1
            yield _Token("name", text[i:end], i)
            i = end
        elif char in "+-*/^()":
            yield _Token("symbol", char, i)
            i += 1
        else:
            raise ExpressionError(f'{_quoted(text)}: unexpected character "{char}" at column {i + 1}')
    yield _Token("end", "", len(text))


def _is_digit(text: str, i: int) -> bool:
    # ASCII only: str.isdigit also takes digits of other scripts and superscripts
    return i < len(text) and text[i] in DIGITS


def _number_end(text: str, start: int) -> int:
    """Index just past the decimal number that starts at start: digits, an optional fraction and
    an optional exponent (1e-3, 2.5E+4)."""
    end = start
    while _is_digit(text, end):
        end += 1
    if text[end : end + 1] == ".":
        end += 1
        while _is_digit(text, end):
            end += 1
    if text[end : end + 1] in ("e", "E"):
        digits = end + 2 if text[end + 1 : end + 2] in ("+", "-") else end + 1
        if not _is_digit(text, digits):
            raise ExpressionError(
                f'{_quoted(text)}: malformed number "{text[start:digits]}" at column {start + 1}: '
                "expected the digits of its exponent"
            )
        end = digits
        while _is_digit(text, end):
            end += 1
    return end


class _Parser:
    """Grammar, loosest binding first:
    terms   = factors (("+" | "-") factors)*
    factors = signed (("*" | "/") signed)*
    signed  = ("+" | "-") signed | power
    power   = atom ("^" signed)?        (right-associative: 2^3^2 = 2^9; -2^2 = -(2^2))
    atom    = number | variable | "pi" | function "(" terms ")" | "(" terms ")"
    """

    def __init__(self, text: str, variables: tuple[str, ...]):
        self.text = text
        self.variables = variables
        self.tokens = _tokens(text)
        self.token = next(self.tokens)
        self.depth = 0

    def parse(self) -> Node:
        tree = self.terms()
        if self.token.kind != "end":
            if self.token.text == ")":
                self.fail(f'unmatched ")" at column {self.token.position + 1}')
            self.expected("an operator (+, -, *, /, ^) or the end")
        return tree

    def advance(self) -> _Token:
        token = self.token
        self.token = next(self.tokens)
        return token

    def fail(self, message: str) -> NoReturn:
        raise ExpressionError(f"{_quoted(self.text)}: {message}")

    def expected(self, what: str, note: str = "") -> NoReturn:
        found = "the end" if self.token.kind == "end" else f'"{self.token.text}"'
        self.fail(f"expected {what} at column {self.token.position + 1}, found {found}{note}")

    def enter(self, opening: _Token):
        """One level deeper, after the opening token; refused past MAX_DEPTH, before Python's own
        recursion limit is reached (about 6 frames a level). The caller leaves it again."""
        self.depth += 1
        if self.depth > MAX_DEPTH:
            where = f'the "{opening.text}" at column {opening.position + 1}'
            self.fail(f"nested more than {MAX_DEPTH} levels deep at {where}")

    def terms(self) -> Node:
        tree = self.factors()
        while self.token.text in ("+", "-"):
            operator = self.advance().text
            tree = Binary(operator, tree, self.factors())
        return tree

    def factors(self) -> Node:
        tree = self.signed()
        while self.token.text in ("*", "/"):
            operator = self.advance().text
            tree = Binary(operator, tree, self.signed())
        return tree

    def signed(self) -> Node:
        if self.token.text in ("+", "-"):
            sign = self.advance()
            self.enter(sign)
            operand = self.signed()
            self.depth -= 1
            return Negate(operand) if sign.text == "-" else operand
        return self.power()

    def power(self) -> Node:
        base = self.atom()
        if self.token.text == "^":
            self.enter(self.advance())
            exponent = self.signed()
            self.depth -= 1
            return Binary("^", base, exponent)
        return base

    def atom(self) -> Node:
        token = self.token
        # each token is checked before the next one is read, which may be an error further on
        if token.kind == "number":
            value = float(token.text)
            if not math.isfinite(value):
                self.fail(f"the number at column {token.position + 1} is too large for a float64")
            self.advance()
            return Number(value)
        if token.kind == "name":
            return self.named()
        if token.text == "(":
            self.advance()
            self.enter(token)
            inner = self.terms()
            self.close(token)
            return inner
        if not self.text.strip():
            self.fail("the expression is empty")
        self.expected(
            f"a number, a variable ({', '.join(self.variables)}), pi, "
            f'a function ({", ".join(FUNCTIONS)}) or "("'
        )

    def named(self) -> Node:  # a variable, a constant or a function call
        token = self.token
        known = (*self.variables, *CONSTANTS, *FUNCTIONS)
        if token.text not in known:
            where = f"at column {token.position + 1}"
            self.fail(f'unknown name "{token.text}" {where}; known: {", ".join(known)}')
        self.advance()
        if token.text in self.variables:
            return Variable(token.text)
        if token.text in CONSTANTS:
            return Number(CONSTANTS[token.text])
        opening = self.token
        if opening.text != "(":
            self.expected(f'"(" after the function {token.text}')
        self.advance()
        self.enter(opening)
        argument = self.terms()
        self.close(opening)
        return Call(token.text, argument)

    def close(self, opening: _Token):
        if self.token.text != ")":
            note = f' (to close the "(" at column {opening.position + 1})'
            self.expected('an operator (+, -, *, /, ^) or ")"', note)
        self.advance()
        self.depth -= 1


@dataclass(frozen=True)
class Expression:
    """A parsed expression: its text as written, the variables it may use, and its tree.
    Expressions are equal when their text and variables are (which fixes the tree)."""

    text: str
    variables: tuple[str, ...]
    # compared and printed through the text: a deep tree would exceed the recursion limit
    tree: Node = field(compare=False, repr=False)

    @property
    def variables_used(self) -> frozenset[str]:
        return frozenset(node.name for node in _postorder(self.tree) if isinstance(node, Variable))

    def evaluate(self, **arrays) -> np.ndarray:
        """The value at every point of the broadcast of the given variables (arrays or numbers of
        broadcastable shapes; unused ones still shape the result), as a new float64 array.
        Raises ExpressionError where the value is not finite, with the first such point."""
        unknown = sorted(set(arrays) - set(self.variables))
        if unknown:
            raise TypeError(f"{_quoted(self.text)} has no variable {', '.join(unknown)}")
        missing = sorted(self.variables_used - set(arrays))
        if missing:
            raise TypeError(f"{_quoted(self.text)} needs a value for {', '.join(missing)}")
        values = {name: np.asarray(value, dtype=np.float64) for name, value in arrays.items()}
        shape = np.broadcast_shapes(*(value.shape for value in values.values()))
        stack = []
        # inf and nan are let through the arithmetic and reported once, for the final value
        # (exp(-1/x^2) at x = 0 passes through -inf to the right limit, 0)
        with np.errstate(all="ignore"):
            for node in _postorder(self.tree):
                if isinstance(node, Number):
                    stack.append(np.float64(node.value))  # numpy, so that 1/0 gives inf, not a raise
                elif isinstance(node, Variable):
                    stack.append(values[node.name])
                elif isinstance(node, Negate):
                    stack.append(np.negative(stack.pop()))
                elif isinstance(node, Call):
                    stack.append(FUNCTIONS[node.function](stack.pop()))
                else:
                    right = stack.pop()
                    stack.append(BINARY[node.operator](stack.pop(), right))
        (result,) = stack
        # an input returned as it is, or a constant, is copied into an array of its own
        if not (isinstance(result, np.ndarray) and result.shape == shape) or any(
            result is value for value in values.values()
        ):
            result = np.broadcast_to(result, shape).copy()
        self._check_finite(result, values)
        return result

    def _check_finite(self, result: np.ndarray, values: dict[str, np.ndarray]):
        finite = np.isfinite(result)
        if finite.all():
            return
        index = tuple(int(i) for i in np.argwhere(~finite)[0])
        point = ", ".join(
            f"{name}={float(np.broadcast_to(value, result.shape)[index])}" for name, value in values.items()
        )
        where = f"at {point}" if point else "everywhere"
        raise ExpressionError(f"{_quoted(self.text)} is not finite ({float(result[index])}) {where}")

    def __str__(self) -> str:
        return self.text


def parse(text: str, variables: tuple[str, ...] = ("x", "y", "z")) -> Expression:
    """The expression written in text, which may use the given variables; ExpressionError with
    the column and what was expected there if it is not one."""
    for name in variables:
        if not name or name[0] not in NAME_START or any(char not in NAME_PART for char in name):
            raise ValueError(f'variable name "{name}" is not a name of letters, digits and _')
        if name in CONSTANTS or name in FUNCTIONS:
            raise ValueError(f'variable name "{name}" is already the name of a constant or function')
    if len(text) > MAX_LENGTH:
        raise ExpressionError(
            f"{_quoted(text)}: {len(text)} characters is longer than the {MAX_LENGTH} allowed"
        )
    return Expression(text, tuple(variables), _Parser(text, tuple(variables)).parse())


def _parseable(variables: tuple[str, ...]):
    def check(text: str) -> str:
        parse(text, variables)
        return text

    return check


def expression_text(variables: tuple[str, ...]):
    """Type of a case-file string that must be an expression of the given variables; it stays
    the string as written, so the resolved case prints it unchanged."""
    return Annotated[str, Field(strict=True), AfterValidator(_parseable(tuple(variables)))]


# an expression of position, such as an initial field (written out rather than made by
# expression_text, so that type checkers see a type)
ExpressionText = Annotated[str, Field(strict=True), AfterValidator(_parseable(("x", "y", "z")))]
