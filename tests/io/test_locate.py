"""Tests for mapping pydantic error locations to lines of a TOML case file."""

import textwrap
import tomllib

import pytest

from sphere_cli.config.locate import find_line, format_location


def case(text: str) -> str:
    """Dedent a TOML snippet and check it is valid TOML, so each test exercises real input."""
    doc = textwrap.dedent(text).lstrip("\n")
    tomllib.loads(doc)
    return doc


def line_of(doc: str, fragment: str) -> int:
    """1-based line of the only line of `doc` that contains `fragment`."""
    hits = [number for number, line in enumerate(doc.splitlines(), 1) if fragment in line]
    assert len(hits) == 1, f"{fragment!r} is on lines {hits}"
    return hits[0]


def test_key_in_table():
    doc = case(
        """
        [simulation]
        duration = 1.0
        dt = 1e-5
        """
    )
    assert find_line(doc, ("simulation", "dt")) == line_of(doc, "dt =")
    assert find_line(doc, ("simulation",)) == line_of(doc, "[simulation]")


def test_top_level_key_before_any_table():
    doc = case(
        """
        title = "demo"
        [simulation]
        dt = 1e-5
        """
    )
    assert find_line(doc, ("title",)) == 1


def test_dotted_table_header():
    doc = case(
        """
        [particles]
        count = 10

        [particles.radius]
        min = 0.1
        max = 0.2
        """
    )
    assert find_line(doc, ("particles", "radius", "min")) == line_of(doc, "min =")
    assert find_line(doc, ("particles", "radius")) == line_of(doc, "[particles.radius]")
    assert find_line(doc, ("particles", "count")) == line_of(doc, "count =")


def test_header_with_spaces_and_quoted_keys():
    doc = case(
        """
        [ output . "h5 file" ]
        "frame rate" = 10
        'raw.key' = 1
        """
    )
    assert find_line(doc, ("output", "h5 file")) == 1
    assert find_line(doc, ("output", "h5 file", "frame rate")) == 2
    assert find_line(doc, ("output", "h5 file", "raw.key")) == 3


def test_implicit_table_points_at_its_explicit_header_when_there_is_one():
    doc = case(
        """
        [particles.radius]
        min = 0.1

        [particles]
        count = 3
        """
    )
    assert find_line(doc, ("particles",)) == line_of(doc, "[particles]")


def test_array_of_tables_counts_occurrences():
    doc = case(
        """
        [[walls]]
        face = "z-"

        [[walls]]
        face = "x-"

        [[walls]]
        face = "x+"
        """
    )
    assert find_line(doc, ("walls", 0, "face")) == line_of(doc, '"z-"')
    assert find_line(doc, ("walls", 2, "face")) == line_of(doc, '"x+"')
    assert find_line(doc, ("walls", 1)) == 4
    assert find_line(doc, ("walls",)) == 1


def test_nested_array_of_tables_and_subtables():
    doc = case(
        """
        [[walls]]
        face = "z-"
        [walls.motion]
        velocity = 0.0

        [[walls]]
        face = "z+"
        [walls.motion]
        velocity = -0.1
        [[walls.sensors]]
        name = "a"
        [[walls.sensors]]
        name = "b"
        """
    )
    assert find_line(doc, ("walls", 0, "motion", "velocity")) == line_of(doc, "= 0.0")
    assert find_line(doc, ("walls", 1, "motion", "velocity")) == line_of(doc, "= -0.1")
    assert find_line(doc, ("walls", 1, "sensors", 1, "name")) == line_of(doc, '"b"')
    assert find_line(doc, ("walls", 0, "sensors")) == 1


def test_dotted_keys():
    doc = case(
        """
        [particles]
        radius.min = 0.1
        radius.max = 0.2
        """
    )
    assert find_line(doc, ("particles", "radius", "max")) == 3
    assert find_line(doc, ("particles", "radius")) == 2


def test_inline_table_resolves_to_its_line():
    doc = case(
        """
        [particles]
        count = 5
        radius = {min = 1, max = 2}
        """
    )
    assert find_line(doc, ("particles", "radius", "min")) == 3
    assert find_line(doc, ("particles", "radius", "max")) == 3
    # A key missing from the inline table falls back to the table's line.
    assert find_line(doc, ("particles", "radius", "mean")) == 3


def test_comments_are_ignored():
    doc = case(
        """
        # [simulation]
        # dt = 1
        [simulation]  # the [clock]
        dt = 1e-5  # [s] = seconds
        duration = 1.0
        """
    )
    assert find_line(doc, ("simulation",)) == 3
    assert find_line(doc, ("simulation", "dt")) == 4
    assert find_line(doc, ("simulation", "duration")) == 5


def test_brackets_inside_multiline_strings_are_not_headers():
    doc = case(
        '''
        [output]
        note = """
        [simulation]
        dt = 1
        """
        raw = \'\'\'
        [[walls]]
        \'\'\'
        format = "h5"
        '''
    )
    assert find_line(doc, ("output", "format")) == line_of(doc, "format =")
    assert find_line(doc, ("simulation",)) is None
    assert find_line(doc, ("walls", 0)) is None
    assert find_line(doc, ("output", "note")) == 2


def test_brackets_inside_strings_and_multiline_arrays():
    doc = case(
        """
        [domain]
        lower = [
          0.0,  # [m]
          "[not a header]",
          0.0,
        ]
        label = "a [b] = c"
        upper = [1, 1, 1]
        """
    )
    assert find_line(doc, ("domain", "upper")) == line_of(doc, "upper =")
    assert find_line(doc, ("domain", "label")) == line_of(doc, "label =")
    assert find_line(doc, ("domain", "lower")) == 2
    assert find_line(doc, ("domain", "lower", 1)) == line_of(doc, '"[not a header]"')


def test_index_into_inline_array_resolves_to_the_key_line():
    doc = case(
        """
        [domain]
        lower = [0, 0, 0]
        upper = [1, 1, 1]
        """
    )
    assert find_line(doc, ("domain", "lower", 1)) == 2
    assert find_line(doc, ("domain", "upper", 2)) == 3
    # An index past the end falls back to the array's line.
    assert find_line(doc, ("domain", "upper", 7)) == 3


def test_index_into_multiline_array_resolves_to_the_element_line():
    doc = case(
        """
        walls = [
          {face = "z-"},
          {face = "z+", velocity = [0, 0, -1]},
        ]
        """
    )
    assert find_line(doc, ("walls", 1, "face")) == 3
    assert find_line(doc, ("walls", 1, "velocity", 2)) == 3
    assert find_line(doc, ("walls", 0)) == 2


def test_missing_key_falls_back_to_enclosing_table():
    doc = case(
        """
        [simulation]
        dt = 1e-5

        [particles]
        count = 4
        """
    )
    assert find_line(doc, ("particles", "radius", "min")) == line_of(doc, "[particles]")
    assert find_line(doc, ("simulation", "duration")) == 1


def test_missing_array_element_falls_back_to_the_array():
    doc = case(
        """
        [[walls]]
        face = "z-"
        [[walls]]
        face = "z+"
        """
    )
    assert find_line(doc, ("walls", 2, "face")) == 1


def test_union_tag_in_path_is_stepped_over():
    doc = case(
        """
        [particles.radius]
        distribution = "uniform"
        min = -1
        """
    )
    # pydantic reports discriminated-union errors as ("particles", "radius", "uniform", "min").
    assert find_line(doc, ("particles", "radius", "uniform", "min")) == 3
    assert find_line(doc, ("particles", "radius", "uniform", "typo")) == 1


def test_union_member_label_in_path_falls_back_to_the_key():
    doc = case(
        """
        [simulation]
        dt = "soon"
        """
    )
    assert find_line(doc, ("simulation", "dt", "float")) == 2
    assert find_line(doc, ("simulation", "dt", "literal['auto']")) == 2


def test_nothing_found_returns_none():
    assert find_line("", ("simulation", "dt")) is None
    assert find_line("# only a comment\n", ("simulation",)) is None
    assert find_line(case("[simulation]\ndt = 1\n"), ("output", "dt")) is None
    assert find_line(case("[simulation]\ndt = 1\n"), ()) is None


def test_crlf_line_endings():
    doc = "[simulation]\r\ndt = 1\r\n\r\nduration = 2\r\n"
    tomllib.loads(doc)
    assert find_line(doc, ("simulation", "duration")) == 4


@pytest.mark.parametrize(
    "doc",
    ["[unclosed\nx = 1\n", 'x = "unterminated\ny = 2\n', "x = [1, 2\n", "= = =\n[[\n", "a = {b"],
)
def test_malformed_input_does_not_raise(doc):
    find_line(doc, ("x",))
    find_line(doc, ("y", 0, "z"))


@pytest.mark.parametrize(
    ("path", "text"),
    [
        (("walls", 2, "face"), "walls[2].face"),
        (("simulation", "dt"), "simulation.dt"),
        (("domain", "lower", 1), "domain.lower[1]"),
        (("walls",), "walls"),
        ((0, "face"), "[0].face"),
        (("output", "frame rate"), 'output."frame rate"'),
        ((), ""),
    ],
)
def test_format_location(path, text):
    assert format_location(path) == text
