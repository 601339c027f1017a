"""The case-file expression language of config/expression.py: precedence, evaluation on numpy
grids, the errors a mistyped or hostile expression gets, and its use as a pydantic field type."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from sphere_cli.config.base import Strict
from sphere_cli.config.expression import (
    MAX_DEPTH,
    MAX_LENGTH,
    Expression,
    ExpressionError,
    ExpressionText,
    expression_text,
    parse,
)


def value(text: str) -> float:
    return float(parse(text).evaluate())


@pytest.mark.parametrize(
    "text, expected",
    [
        ("1+2*3", 7.0),
        ("(1+2)*3", 9.0),
        ("2^3^2", 512.0),  # right-associative: 2^(3^2)
        ("(2^3)^2", 64.0),
        ("-2^2", -4.0),  # the power before the sign, as in mathematics
        ("(-2)^2", 4.0),
        ("2^-1", 0.5),
        ("2*-3", -6.0),
        ("(1-2)-3", -4.0),
        ("1-2-3", -4.0),  # left-associative
        ("8/4/2", 1.0),
        ("2*3^2", 18.0),
        ("-3", -3.0),
        ("--3", 3.0),
        ("+-+3", -3.0),
        ("1 -\t-1\n", 2.0),  # whitespace of any kind is ignored
        ("1e-3", 1e-3),
        ("2.5E+4", 2.5e4),
        ("3e2", 300.0),
        (".5", 0.5),
        ("5.", 5.0),
        ("007", 7.0),
    ],
)
def test_precedence_associativity_and_numbers(text, expected):
    assert value(text) == expected


def test_functions_and_pi():
    assert value("sin(pi/2)") == 1.0
    assert value("exp(0)") == 1.0
    assert value("cos(0)") == 1.0
    assert value("pi") == math.pi
    assert value("exp(1)") == math.e
    assert value("-sin(-pi/2)^2") == -1.0
    assert value("cos(sin(0))*exp(cos(pi)+1)") == 1.0


def test_grid_matches_numpy_computed_the_same_way():
    x, y = np.meshgrid(np.linspace(0.0, 1.0, 17), np.linspace(-0.5, 0.5, 9), indexing="ij")
    field = parse("sin(2*pi*x)*cos(2*pi*y)").evaluate(x=x, y=y)
    assert field.dtype == np.float64 and field.shape == (17, 9)
    np.testing.assert_array_equal(field, np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y))

    x, y, z = (
        np.linspace(0.0, 1.0, 17)[:, None, None],
        np.linspace(0.0, 1.0, 9)[:, None],
        np.linspace(0.1, 2.0, 5),
    )
    field = parse("exp(-z/2) * x^2 - 1e-3/z + y").evaluate(x=x, y=y, z=z)
    assert field.shape == (17, 9, 5)
    np.testing.assert_array_equal(field, np.exp(-z / 2) * x**2 - 1e-3 / z + y)


def test_result_has_the_broadcast_shape_of_every_variable_given():
    x = np.linspace(0.0, 1.0, 4)[:, None, None]
    y = np.linspace(0.0, 1.0, 3)[None, :, None]
    z = np.linspace(0.0, 1.0, 2)[None, None, :]

    constant = parse("2*pi").evaluate(x=x, y=y, z=z)
    assert constant.shape == (4, 3, 2)
    assert np.all(constant == 2 * np.pi)

    only_x = parse("x + 1").evaluate(x=x, y=y, z=z)
    assert only_x.shape == (4, 3, 2)
    np.testing.assert_array_equal(only_x, np.broadcast_to(x + 1, (4, 3, 2)))

    assert parse("3").evaluate().shape == ()
    assert parse("x*y").evaluate(x=2.0, y=[1.0, 2.0]).tolist() == [2.0, 4.0]


def test_result_is_a_new_array():
    x = np.linspace(0.0, 1.0, 5)
    same = parse("x").evaluate(x=x)
    assert same is not x and not np.shares_memory(same, x)
    np.testing.assert_array_equal(same, x)
    parse("1").evaluate(x=x)[0] = 5.0  # writable, not a read-only broadcast view


def test_variables_used_and_custom_variables():
    assert parse("sin(x)*pi + 2").variables_used == {"x"}
    assert parse("x*z - z").variables_used == {"x", "z"}
    assert parse("4").variables_used == frozenset()

    with_time = parse("x*exp(-t)", ("x", "y", "z", "t"))
    assert with_time.variables_used == {"x", "t"}
    np.testing.assert_array_equal(with_time.evaluate(x=np.ones(3), t=0.0), np.ones(3))
    with pytest.raises(ExpressionError, match='unknown name "t" at column 8'):
        parse("x*exp(-t)")


def test_evaluate_names_missing_or_unknown_variables():
    with pytest.raises(TypeError, match="needs a value for y"):
        parse("x+y").evaluate(x=1.0)
    with pytest.raises(TypeError, match="has no variable t"):
        parse("x").evaluate(x=1.0, t=0.0)


def test_parse_refuses_variables_that_are_not_names_or_are_taken():
    with pytest.raises(ValueError, match="not a name"):
        parse("1", ("x", "2y"))
    with pytest.raises(ValueError, match="constant or function"):
        parse("1", ("x", "pi"))


def test_expression_keeps_its_text_and_compares_by_it():
    expression = parse(" 1 + x ")
    assert isinstance(expression, Expression)
    assert expression.text == str(expression) == " 1 + x "
    assert expression == parse(" 1 + x ") and hash(expression) == hash(parse(" 1 + x "))
    assert expression != parse("1+x")
    with pytest.raises(AttributeError):
        expression.text = "2"


def test_long_flat_sums_need_no_deep_recursion():
    # a left-leaning tree as deep as the text is long: evaluated, compared and hashed without
    # Python recursion
    text = "1+" * (MAX_LENGTH // 2 - 1) + "1"
    assert value(text) == MAX_LENGTH // 2
    assert parse(text) == parse(text) and isinstance(hash(parse(text)), int)


@pytest.mark.parametrize(
    "text, message",
    [
        ("", '"": the expression is empty'),
        ("   ", '"   ": the expression is empty'),
        (
            "2*x +",
            '"2*x +": expected a number, a variable (x, y, z), pi, a function (sin, cos, exp) or "(" '
            "at column 6, found the end",
        ),
        (
            "2*/x",
            '"2*/x": expected a number, a variable (x, y, z), pi, a function (sin, cos, exp) or "(" '
            'at column 3, found "/"',
        ),
        (
            "(1+2",
            '"(1+2": expected an operator (+, -, *, /, ^) or ")" at column 5, found the end '
            '(to close the "(" at column 1)',
        ),
        ("1+2)", '"1+2)": unmatched ")" at column 4'),
        (
            "()",
            '"()": expected a number, a variable (x, y, z), pi, a function (sin, cos, exp) or "(" '
            'at column 2, found ")"',
        ),
        ("x+r", '"x+r": unknown name "r" at column 3; known: x, y, z, pi, sin, cos, exp'),
        ("sqrt(x)", '"sqrt(x)": unknown name "sqrt" at column 1; known: x, y, z, pi, sin, cos, exp'),
        ("sin x", '"sin x": expected "(" after the function sin at column 5, found "x"'),
        ("2*cos", '"2*cos": expected "(" after the function cos at column 6, found the end'),
        (
            "exp(1",
            '"exp(1": expected an operator (+, -, *, /, ^) or ")" at column 6, found the end '
            '(to close the "(" at column 4)',
        ),
        ("2 3", '"2 3": expected an operator (+, -, *, /, ^) or the end at column 3, found "3"'),
        ("2x", '"2x": expected an operator (+, -, *, /, ^) or the end at column 2, found "x"'),
        ("x y", '"x y": expected an operator (+, -, *, /, ^) or the end at column 3, found "y"'),
        ("1..2", '"1..2": expected an operator (+, -, *, /, ^) or the end at column 3, found ".2"'),
        (
            "x**2",
            '"x**2": expected a number, a variable (x, y, z), pi, a function (sin, cos, exp) or "(" '
            'at column 3, found "*"',
        ),
        ("1e", '"1e": malformed number "1e" at column 1: expected the digits of its exponent'),
        ("2.5E+", '"2.5E+": malformed number "2.5E+" at column 1: expected the digits of its exponent'),
        ("1e400", '"1e400": the number at column 1 is too large for a float64'),
        ("x % 2", '"x % 2": unexpected character "%" at column 3'),
        ("x²", '"x²": unexpected character "²" at column 2'),
    ],
)
def test_syntax_errors_quote_the_text_and_name_the_column(text, message):
    with pytest.raises(ExpressionError) as caught:
        parse(text)
    assert str(caught.value) == message
    assert isinstance(caught.value, ValueError)


@pytest.mark.parametrize(
    "text, message",
    [
        ("__import__('os')", 'unknown name "__import__" at column 1'),
        ("__import__('os').system('true')", 'unknown name "__import__" at column 1'),
        ("x.real", 'unexpected character "." at column 2'),
        ("x.__class__", 'unexpected character "." at column 2'),
        ("[x]", 'unexpected character "[" at column 1'),
        ("lambda: 1", 'unknown name "lambda" at column 1'),
        ("x if 1 else 2", 'expected an operator (+, -, *, /, ^) or the end at column 3, found "if"'),
        ("'1'", 'unexpected character "\'" at column 1'),
        ("1; x", 'unexpected character ";" at column 2'),
        ("sin.__globals__", 'unexpected character "." at column 4'),
    ],
)
def test_python_is_not_accepted(text, message):
    with pytest.raises(ExpressionError) as caught:
        parse(text)
    assert str(caught.value).startswith(f'"{text}": ') and message in str(caught.value)


def test_too_long():
    longest = "1+" * (MAX_LENGTH // 2 - 1) + "1 "
    assert len(longest) == MAX_LENGTH
    parse(longest)
    with pytest.raises(ExpressionError, match=f"{MAX_LENGTH + 1} characters is longer than the {MAX_LENGTH}"):
        parse(longest + " ")


def test_long_number_is_not_repeated_in_the_message():
    with pytest.raises(ExpressionError) as caught:
        parse("x+" + "9" * 400)
    assert str(caught.value).endswith(
        '..." (402 characters): the number at column 3 is too large for a float64'
    )


@pytest.mark.parametrize(
    "opening, closing",
    [("(", ")"), ("sin(", ")"), ("-", ""), ("2^", "")],
)
def test_too_deep_nesting_is_an_expression_error_not_a_recursion_error(opening, closing):
    parse(opening * MAX_DEPTH + "1" + closing * MAX_DEPTH)
    too_deep = opening * (MAX_DEPTH + 1) + "1" + closing * (MAX_DEPTH + 1)
    with pytest.raises(ExpressionError, match=f"nested more than {MAX_DEPTH} levels deep at the"):
        parse(too_deep)


def test_deepest_expression_leaves_room_on_the_stack():
    # a case file is parsed under the command line, pydantic and pytest: 200 frames of callers
    # stand for them
    def parse_from_below(frames: int):
        return parse_from_below(frames - 1) if frames else parse("sin(" * MAX_DEPTH + "x" + ")" * MAX_DEPTH)

    assert parse_from_below(200).evaluate(x=0.0) == 0.0


def test_long_text_is_cut_in_the_message():
    with pytest.raises(ExpressionError) as caught:
        parse("1+" * 100 + "r")
    message = str(caught.value)
    assert message.startswith('"1+1+') and '..." (201 characters)' in message
    assert 'unknown name "r" at column 201' in message


def test_not_finite_values_raise_with_the_first_point():
    x = np.array([1.0, 0.5, 0.0, 0.0])
    y = np.array([[2.0], [3.0]])
    with pytest.raises(ExpressionError) as caught:
        parse("1/x").evaluate(x=x, y=y)
    assert str(caught.value) == '"1/x" is not finite (inf) at x=0.0, y=2.0'

    with pytest.raises(ExpressionError, match=r'^"0/0" is not finite \(nan\) everywhere$'):
        parse("0/0").evaluate()
    with pytest.raises(ExpressionError, match=r"not finite \(inf\) at x=1000.0$"):
        parse("exp(x)").evaluate(x=[1.0, 1000.0])
    with pytest.raises(ExpressionError, match=r"not finite \(nan\) at x=-1.0$"):
        parse("x^0.5").evaluate(x=[4.0, -1.0])
    with pytest.raises(ExpressionError, match=r"not finite \(nan\) at x=0.5, y=0.0, z=0.25$"):
        parse("y/y").evaluate(x=0.5, y=np.array([1.0, 0.0]), z=0.25)


def test_non_finite_intermediates_with_a_finite_result_pass():
    # exp(-1/x^2) -> 0 as x -> 0; numpy reaches it through -inf, without warnings or errors
    with np.errstate(all="raise"):
        result = parse("exp(-1/x^2)").evaluate(x=np.array([0.0, 1.0]))
    np.testing.assert_array_equal(result, [0.0, math.exp(-1.0)])


ExpressionOfTime = expression_text(("x", "y", "z", "t"))


class Initial(Strict):
    velocity: ExpressionText = "0"
    source: ExpressionOfTime = "0"


def test_pydantic_field_accepts_good_text_and_keeps_it():
    model = Initial.model_validate({"velocity": "sin(2*pi*x) * cos(2*pi*y)", "source": "exp(-t)"})
    assert model.velocity == "sin(2*pi*x) * cos(2*pi*y)"
    assert model.model_dump(mode="json") == {"velocity": "sin(2*pi*x) * cos(2*pi*y)", "source": "exp(-t)"}
    assert Initial().velocity == "0"


def test_pydantic_field_rejects_bad_text_with_the_expression_message():
    with pytest.raises(ValidationError) as caught:
        Initial.model_validate({"velocity": "2*x +"})
    (error,) = caught.value.errors(include_url=False)
    assert error["loc"] == ("velocity",)
    assert isinstance(error["ctx"]["error"], ExpressionError)
    assert error["msg"] == "Value error, " + str(parse_error("2*x +"))

    with pytest.raises(ValidationError, match='unknown name "t" at column 1'):
        Initial.model_validate({"velocity": "t"})
    with pytest.raises(ValidationError, match="string_type"):
        Initial.model_validate({"velocity": 1.0})  # a TOML number is not an expression string


def parse_error(text: str) -> ExpressionError:
    with pytest.raises(ExpressionError) as caught:
        parse(text)
    return caught.value
