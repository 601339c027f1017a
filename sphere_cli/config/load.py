"""Read a TOML case file into a validated `Case`, with errors that name the key, value and line,
and warnings (stderr) about values that are allowed but probably not meant.

Also: the resolved case as a plain dict (every default filled in), its rendering as a tree,
and the hash of the physics-relevant part that `resume` compares against a checkpoint.

Hostile input stays cheap: the file is read only if it is a regular file of at most
MAX_CASE_BYTES, nesting is bounded, and the lines of the keys are found in one scan whatever
the number of errors, of which the first MAX_ERRORS are reported.
"""

from __future__ import annotations

import copy
import hashlib
import io
import json
import logging
import re
import stat
import sys
from dataclasses import dataclass
from pathlib import Path

import tomli
from pydantic import ValidationError

from ..errors import CaseError, MissingInputError, SphereError
from .consistency import case_warnings, check_consistency
from .fluid_common import RENAMED
from .locate import KeyLines, format_location
from .schema import NON_PHYSICS_KEYS, Case, Strict

# Case files are a few kB (the particles of a large scene come from a placement file); 1 MiB,
# some 12 000 stages, still validates in about a second, where 16 MiB would take fifteen.
MAX_CASE_BYTES = 2**20
# Tables and arrays within each other: a case needs five levels (stages[0].walls[0].face);
# far deeper input would exhaust the recursion of the validation and of the messages.
MAX_DEPTH = 32
MAX_ERRORS = 20  # error lines reported; the rest are counted


@dataclass(frozen=True)
class LoadedCase:
    case: Case
    text: str
    path: Path | None
    # the case file a run was started from, when this is the run directory's copy: its folder
    # resolves the case's relative paths (pressure series, field files) on resume
    origin: Path | None = None

    @property
    def base_dir(self) -> Path:
        if self.origin is not None:
            return self.origin.parent
        return self.path.parent if self.path is not None else Path.cwd()

    def describe(self, loc: tuple, message: str) -> str:
        """`case.toml:LINE: key = value: message` about the key at `loc`."""
        where = str(self.path) if self.path is not None else "<case>"
        data = tomli.loads(self.text)
        return _one_error(where, KeyLines(self.text), loc, _value_at(data, loc), message)

    def error(self, loc: tuple, message: str) -> CaseError:
        """A CaseError about the key at `loc`, found while building the scene."""
        return CaseError(self.describe(loc, message))


# the case's warnings also reach run.log while a run's log is open (io/rundir.py listens to this
# logger); they print themselves, so they go nowhere else: not up to a notebook's root handler,
# and the null handler keeps logging's last resort from printing them a second time
CASE_LOG = logging.getLogger("sphere.case")
CASE_LOG.addHandler(logging.NullHandler())
CASE_LOG.propagate = False


def warn(message: str) -> None:
    """Tell the user (stderr, and run.log during a run) of something in the case that is allowed
    but probably not meant."""
    text = f"sphere: warning: {message}"
    print(text, file=sys.stderr)
    CASE_LOG.warning("%s", text, extra={"printed": True})


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a named pipe"),
    (stat.S_ISSOCK, "a socket"),
)


def load_case(path: str | Path) -> LoadedCase:
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            # a device or pipe could be endless or block: not opened at all
            kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
            raise MissingInputError(f"{path}: is {kind}; a case file is a TOML text file")
        with path.open("rb") as file:
            data = file.read(MAX_CASE_BYTES + 1)
    except FileNotFoundError:
        raise MissingInputError(f"{path}: case file not found") from None
    except OSError as exc:
        raise MissingInputError(f"{path}: cannot read case file ({exc.strerror or exc})") from None
    if len(data) > MAX_CASE_BYTES:
        raise CaseError(
            f"{path}: larger than {MAX_CASE_BYTES // 2**20} MiB, the most a case file may hold "
            "(the particles of a large scene come from particles.placement.path)"
        )
    try:
        # decoded as read_text would, universal newlines included; a byte-order mark (Windows
        # editors write one) is dropped, as TOML readers do
        text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig").read()
    except UnicodeDecodeError as exc:
        raise CaseError(f"{path}: a case file must be UTF-8 text ({exc})") from None
    return parse_case(text, path)


def parse_case(text: str, path: Path | None = None, show_warnings: bool = True) -> LoadedCase:
    """The case in `text` validated (`path` names it in messages); its warnings printed unless
    `show_warnings` is False (a caller that reports them itself: sphere_cli/sweep.py)."""
    where = str(path) if path is not None else "<case>"
    try:
        data = tomli.loads(text)
    except tomli.TOMLDecodeError as exc:
        line = getattr(exc, "lineno", None)
        if line is None:
            raise CaseError(f"{where}: not valid TOML: {exc}") from None
        raise CaseError(f"{where}:{line}: not valid TOML: {exc.msg} (column {exc.colno})") from None
    except RecursionError as exc:  # tomli's own limits: 400 levels of nesting, 1000 parts of a key
        raise CaseError(f"{where}: not a usable case file: {exc}") from None
    deep = _too_deep(data)
    if deep is not None:
        message = f"nested more than {MAX_DEPTH} tables or arrays deep (a case needs five levels)"
        raise CaseError(_report(where, text, [(deep, _MISSING, message)]))
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        raise CaseError(_report(where, text, _validation_errors(exc, data))) from None
    problems = check_consistency(case)
    if problems:
        raise CaseError(_report(where, text, [(loc, _value_at(data, loc), msg) for loc, msg in problems]))
    warnings = case_warnings(case) if show_warnings else []
    if warnings:
        lines = KeyLines(text)
        for loc, message in warnings:
            warn(_one_error(where, lines, loc, _value_at(data, loc), message))
    _remember_source(case, (where, text))
    return LoadedCase(case=case, text=text, path=path)


def _too_deep(data) -> tuple | None:
    """The key path of a value nested deeper than MAX_DEPTH (None if none is), found without
    recursion."""
    stack = [((), data)]
    while stack:
        loc, node = stack.pop()
        if len(loc) > MAX_DEPTH:
            return loc
        if isinstance(node, dict):
            stack.extend(((*loc, key), value) for key, value in node.items())
        elif isinstance(node, list):
            stack.extend(((*loc, i), value) for i, value in enumerate(node))
    return None


def _report(where: str, text: str, errors: list[tuple[tuple, object, str]]) -> str:
    """One line per (loc, value, message), the first MAX_ERRORS of them."""
    lines = KeyLines(text)
    shown = [_one_error(where, lines, loc, value, message) for loc, value, message in errors[:MAX_ERRORS]]
    if len(errors) > MAX_ERRORS:
        shown.append(f"... and {len(errors) - MAX_ERRORS} more errors")
    return "\n".join(shown)


def _remember_source(model, source: tuple[str, str]) -> None:
    """Tell every part of the case which file and text it came from (see `case_error`)."""
    if isinstance(model, Strict):
        model._source = source
        for name in type(model).model_fields:
            _remember_source(getattr(model, name), source)
    elif isinstance(model, list | tuple):
        for item in model:
            _remember_source(item, source)


def case_error(model, loc: tuple, message: str, error=CaseError) -> SphereError:
    """An error about the key at `loc` (a path from the top of the case), found after loading,
    e.g. while building the scene. `model` is any part of a loaded case: the message then starts
    with `case.toml:LINE: key = value:`, as the errors of loading do."""
    source = getattr(model, "_source", None)
    if source is None:
        return error(f"{format_location(loc)}: {message}")
    where, text = source
    try:
        value = _value_at(tomli.loads(text), loc)
    except tomli.TOMLDecodeError:
        value = _MISSING
    return error(_one_error(where, KeyLines(text), loc, value, message))


def _one_error(where: str, lines: KeyLines, loc: tuple, value, message: str) -> str:
    line = lines.find(loc)
    place = f"{where}:{line}" if line else where
    key = format_location(loc) if loc else "(top level)"
    shown = "" if value is _MISSING else f" = {_toml_value(value)}"
    return f"{place}: {key}{shown}: {message}"


_MISSING = object()


def _toml_value(value) -> str:
    """A value as it would be written in TOML, for messages (long tables and arrays elided)."""
    text = toml_text(value)
    return text if len(text) <= 80 else text[:76] + " ..."


def toml_text(value) -> str:
    """A value written in TOML (inline tables and arrays; None, not set, is left out of tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON's escapes are TOML's
    if isinstance(value, dict):
        items = [f"{_toml_key(k)} = {toml_text(v)}" for k, v in value.items() if v is not None]
        return "{ " + ", ".join(items) + " }" if items else "{}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_text(v) for v in value) + "]"
    return repr(value) if isinstance(value, float) else str(value)


def _value_at(data, loc: tuple):
    node = data
    for part in loc:
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            return _MISSING
    return node


def _clean_location(data, loc: tuple) -> tuple:
    """Drop the union tags pydantic inserts (e.g. 'uniform' in particles.radius.uniform.min). A
    tag that is also a key of the table (the "pressure" boundary has a `pressure`) is told apart
    by what follows it: a tag is followed by keys, a plain value is not."""
    cleaned, node = [], data
    for i, part in enumerate(loc):
        found = (isinstance(node, dict) and part in node) or (
            isinstance(node, list) and isinstance(part, int) and part < len(node)
        )
        if found and i < len(loc) - 1 and not isinstance(node[part], (dict, list)):
            found = False
        if found:
            cleaned.append(part)
            node = node[part]
        elif i == len(loc) - 1:
            cleaned.append(part)  # a required key that the file lacks
    return tuple(cleaned)


def _validation_errors(exc: ValidationError, data) -> list[tuple[tuple, object, str]]:
    """(loc, value, message) of each error pydantic found, worded for a case file."""
    errors = []
    for err in exc.errors(include_url=False):
        loc = _clean_location(data, tuple(err["loc"]))
        message = err["msg"]
        if err["type"] == "extra_forbidden" and loc in RENAMED:
            message = f"a key of earlier versions, now {RENAMED[loc]}"
        elif err["type"] == "extra_forbidden":
            message = "unknown key (check the spelling; `sphere schema` lists every key)"
        elif err["type"] == "missing":
            message = "required key is missing"
        elif err["type"] == "union_tag_invalid":
            ctx = err.get("ctx", {})
            loc += (ctx.get("discriminator", "").strip("'"),)
            message = "unknown choice; expected one of " + ctx.get("expected_tags", "").replace("'", '"')
        elif err["type"] == "union_tag_not_found":
            loc += (err.get("ctx", {}).get("discriminator", "").strip("'"),)
            message = "required key is missing (it selects the kind; `sphere schema` lists the choices)"
        elif err["type"] == "too_long":
            ctx = err.get("ctx", {})
            message = f"{ctx.get('actual_length')} entries; at most {ctx.get('max_length')} are allowed"
        elif message.startswith("Value error, "):
            message = message[len("Value error, ") :]
        value = _value_at(data, loc) if err["type"] not in ("missing", "union_tag_not_found") else _MISSING
        errors.append((loc, value, message))
    return errors


def resolved_dict(case: Case) -> dict:
    """The case with every default filled in, as plain JSON-compatible data."""
    return case.model_dump(mode="json")


# keys of files a run reads again when it resumes (the initial state's files it does not)
RESUMED_FILES = (
    ("fluid", "bottom", "series"),
    ("fluid", "top", "series"),
    ("fluid", "body_force", "file"),
    ("fluid", "bed", "file"),
)


def run_record(loaded: LoadedCase) -> dict:
    """What a run records of its case (trajectory and checkpoints) and hashes for the physics:
    the resolved case, and under "input_files" the SHA-256 of each file it reads again on resume
    (a pressure series, a body-force field), so that an edited file is refused like an edited key.
    A file that cannot be read is left out (building the scene names it)."""
    record = resolved_dict(loaded.case)
    files = {}
    for key in RESUMED_FILES:
        name = _value_at(record, key)
        if isinstance(name, str):
            path = Path(name) if Path(name).is_absolute() else loaded.base_dir / name
            try:
                files[".".join(key)] = hashlib.sha256(path.read_bytes()).hexdigest()
            except OSError:
                continue
    if files:
        record["input_files"] = files
    return record


def physics_hash(resolved: dict) -> str:
    """SHA-256 of the part of the case that changes the physics (output, duration excluded)."""
    physics = copy.deepcopy(resolved)
    for key in NON_PHYSICS_KEYS:
        node = physics
        for part in key[:-1]:
            node = node.get(part) or {}  # (a table absent, or None: a case without a fluid)
        node.pop(key[-1], None)
    blob = json.dumps(physics, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()


def render_toml(data: dict) -> str:
    """The resolved case as TOML that loads back to the same case: tables for dicts, arrays of
    tables for lists of dicts, keys whose value is None (not set) left out."""
    out: list[str] = []
    _toml_table(data, (), out)
    return "\n".join(out).strip() + "\n"


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(key) -> str:
    key = str(key)
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key, ensure_ascii=False)


def _is_table_array(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _toml_table(table: dict, path: tuple, out: list[str]) -> None:
    nested = []
    for key, value in table.items():
        if value is None:
            continue
        if (isinstance(value, dict) and value) or _is_table_array(value):
            nested.append((key, value))
        else:
            out.append(f"{_toml_key(key)} = {toml_text(value)}")
    for key, value in nested:
        name = ".".join(_toml_key(k) for k in (*path, key))
        for item in value if isinstance(value, list) else [value]:
            out.append("")
            out.append(f"[[{name}]]" if isinstance(value, list) else f"[{name}]")
            _toml_table(item, (*path, key), out)
