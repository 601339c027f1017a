"""Map a validation error location (a pydantic ``loc`` tuple) to a line of the TOML case file.

The scanner here is not a TOML parser: it walks the text once, tracking table headers,
keys, strings, comments and brackets, and records the line on which each key path is
first defined. Malformed input is tolerated: it records what it can and does not raise.
"""

import re

KeyPath = tuple[str | int, ...]

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_SCALAR_END = frozenset(",]}#\n")
_BASIC_ESCAPES = {"b": "\b", "t": "\t", "n": "\n", "f": "\f", "r": "\r", '"': '"', "\\": "\\"}


def find_line(toml_text: str, path: KeyPath) -> int | None:
    """Return the 1-based line where the value at `path` is defined in `toml_text`.

    `path` holds table keys (str) and array indices (int), as in a pydantic error's
    ``loc``. A key pydantic inserts that the document does not hold (a union tag such as
    ``"uniform"`` in ("particles", "radius", "uniform", "min"), or a member type such as
    ``"float"``) is stepped over when the element after it is found. When the full path is
    not in the document, the line of the deepest enclosing key or table that is present is
    returned; None when nothing matches.
    """
    return KeyLines(toml_text).find(path)


class KeyLines:
    """The lines of every key path of a TOML document, scanned once: `find` is `find_line`
    without the scan, so locating many errors in one document stays linear in its size."""

    def __init__(self, toml_text: str) -> None:
        scanner = _DocumentScanner(toml_text)
        try:
            scanner.scan()
        except RecursionError:  # inline tables nested deeper than the stack: keep what was found
            pass
        self.lines = scanner.lines

    def find(self, path: KeyPath) -> int | None:
        lines = self.lines
        matched: KeyPath = ()
        index = 0
        while index < len(path):
            candidate = matched + (path[index],)
            if candidate in lines:
                matched = candidate
                index += 1
            elif (
                matched
                and isinstance(path[index], str)
                and index + 1 < len(path)
                and matched + (path[index + 1],) in lines
            ):
                index += 1
            else:
                break
        return lines[matched] if matched else None


def format_location(path: KeyPath) -> str:
    """Render a key path for messages: ("walls", 2, "face") -> ``walls[2].face``.

    Keys that are not bare TOML keys are double-quoted; the empty path renders as "".
    """
    parts: list[str] = []
    for element in path:
        if isinstance(element, int) and not isinstance(element, bool):
            parts.append(f"[{element}]")
            continue
        key = str(element)
        if not _BARE_KEY.fullmatch(key):
            key = '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'
        parts.append(("." if parts else "") + key)
    return "".join(parts)


class _DocumentScanner:
    """One pass over a TOML document, recording the first line of every key path."""

    def __init__(self, text: str) -> None:
        self.text = text[1:] if text.startswith("\ufeff") else text
        self.pos = 0
        self.line = 1
        self.lines: dict[KeyPath, int] = {}
        self.explicit: set[KeyPath] = set()
        self.table: KeyPath = ()
        self.array_lengths: dict[KeyPath, int] = {}

    # -- document --------------------------------------------------------------------------

    def scan(self) -> dict[KeyPath, int]:
        while self.pos < len(self.text):
            start = self.pos
            self.skip_blank_lines()
            if self.pos >= len(self.text):
                break
            if self.text.startswith("[[", self.pos):
                self.array_table_header()
            elif self.peek() == "[":
                self.table_header()
            else:
                self.key_value(self.table)
            self.skip_rest_of_line()
            if self.pos == start:
                self.advance()
        return self.lines

    def record(self, path: KeyPath, line: int, explicit: bool = False) -> None:
        """Record `path` and its prefixes; an explicit header wins over an implied prefix."""
        for depth in range(1, len(path) + 1):
            prefix = path[:depth]
            if prefix not in self.lines:
                self.lines[prefix] = line
        if explicit and path not in self.explicit:
            self.explicit.add(path)
            self.lines[path] = line

    # -- statements --------------------------------------------------------------------------

    def table_header(self) -> None:
        line = self.line
        self.advance()
        keys = self.dotted_key()
        if not keys:
            return
        self.table = self.resolve(keys)
        self.record(self.table, line, explicit=True)

    def array_table_header(self) -> None:
        line = self.line
        self.advance(2)
        keys = self.dotted_key()
        if not keys:
            return
        array = self.resolve(keys[:-1]) + (keys[-1],)
        index = self.array_lengths.get(array, 0)
        self.array_lengths[array] = index + 1
        self.table = array + (index,)
        self.record(array, line)
        self.record(self.table, line, explicit=True)

    def resolve(self, keys: list[str]) -> KeyPath:
        """Turn header keys into a path, stepping into the latest element of arrays of tables."""
        path: KeyPath = ()
        for key in keys:
            path += (key,)
            length = self.array_lengths.get(path)
            if length:
                path += (length - 1,)
        return path

    def key_value(self, parent: KeyPath) -> bool:
        """Scan ``key = value`` and record it under `parent`; False if no key was found."""
        line = self.line
        keys = self.dotted_key()
        if not keys:
            return False
        self.skip_spaces()
        if self.peek() != "=":
            return False
        self.advance()
        self.skip_spaces()
        path = parent + tuple(keys)
        self.record(path, line)
        self.value(path)
        return True

    # -- keys --------------------------------------------------------------------------------

    def dotted_key(self) -> list[str]:
        keys: list[str] = []
        while True:
            self.skip_spaces()
            key = self.simple_key()
            if key is None:
                return keys
            keys.append(key)
            self.skip_spaces()
            if self.peek() != ".":
                return keys
            self.advance()

    def simple_key(self) -> str | None:
        char = self.peek()
        if char == '"':
            return self.basic_string()
        if char == "'":
            return self.literal_string()
        match = _BARE_KEY.match(self.text, self.pos)
        if match is None:
            return None
        self.pos = match.end()
        return match.group()

    # -- values ------------------------------------------------------------------------------

    def value(self, path: KeyPath) -> None:
        char = self.peek()
        if char == "[":
            self.array(path)
        elif char == "{":
            self.inline_table(path)
        elif self.text.startswith('"""', self.pos):
            self.multiline_string('"""', escapes=True)
        elif self.text.startswith("'''", self.pos):
            self.multiline_string("'''", escapes=False)
        elif char == '"':
            self.basic_string()
        elif char == "'":
            self.literal_string()
        else:
            while self.pos < len(self.text) and self.peek() not in _SCALAR_END:
                self.advance()

    def array(self, path: KeyPath) -> None:
        self.advance()
        index = 0
        while True:
            self.skip_blank_lines()
            char = self.peek()
            if char in ("]", ""):
                self.advance()
                return
            if char == ",":
                self.advance()
                continue
            start = self.pos
            element = path + (index,)
            self.record(element, self.line)
            self.value(element)
            index += 1
            if self.pos == start:
                self.advance()

    def inline_table(self, path: KeyPath) -> None:
        self.advance()
        while True:
            self.skip_blank_lines()
            char = self.peek()
            if char in ("}", ""):
                self.advance()
                return
            if char == ",":
                self.advance()
                continue
            start = self.pos
            if not self.key_value(path) and self.pos == start:
                self.advance()

    def basic_string(self) -> str:
        self.advance()
        chars: list[str] = []
        while self.pos < len(self.text):
            char = self.peek()
            if char == "\n":
                break
            if char == '"':
                self.advance()
                break
            if char == "\\":
                self.advance()
                escaped = self.peek()
                chars.append(_BASIC_ESCAPES.get(escaped, "\\" + escaped))
                self.advance()
                continue
            chars.append(char)
            self.advance()
        return "".join(chars)

    def literal_string(self) -> str:
        self.advance()
        end = self.text.find("'", self.pos)
        newline = self.text.find("\n", self.pos)
        if end < 0 or 0 <= newline < end:
            end = newline if newline >= 0 else len(self.text)
            content = self.text[self.pos : end]
            self.pos = end
            return content
        content = self.text[self.pos : end]
        self.pos = end + 1
        return content

    def multiline_string(self, delimiter: str, escapes: bool) -> None:
        self.advance(3)
        while self.pos < len(self.text):
            if escapes and self.peek() == "\\":
                self.advance(2)
            elif self.text.startswith(delimiter, self.pos):
                self.advance(3)
                # Up to two quotes may sit right before the closing delimiter.
                for _ in range(2):
                    if self.peek() == delimiter[0]:
                        self.advance()
                return
            else:
                self.advance()

    # -- low-level movement ------------------------------------------------------------------

    def peek(self) -> str:
        return self.text[self.pos] if self.pos < len(self.text) else ""

    def advance(self, count: int = 1) -> None:
        end = min(self.pos + count, len(self.text))
        self.line += self.text.count("\n", self.pos, end)
        self.pos = end

    def skip_spaces(self) -> None:
        while self.peek() in (" ", "\t"):
            self.pos += 1

    def skip_blank_lines(self) -> None:
        """Skip whitespace, newlines and comments."""
        while self.pos < len(self.text):
            char = self.peek()
            if char in (" ", "\t", "\r", "\n"):
                self.advance()
            elif char == "#":
                self.skip_rest_of_line()
            else:
                return

    def skip_rest_of_line(self) -> None:
        newline = self.text.find("\n", self.pos)
        self.pos = len(self.text) if newline < 0 else newline
