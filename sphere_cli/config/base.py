"""Building blocks of the case-file schema shared by every section (schema.py and the fluid
model files): strict numbers, the forbidding base model, and tagged-union defaults."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, PrivateAttr


def _int64(value: int) -> int:
    # TOML integers are 64-bit, but tomli reads any length; larger ones would overflow the
    # float and int64 arithmetic of the checks and the arrays
    if not -(2**63) <= value < 2**63:
        raise ValueError(f"TOML integers are 64-bit: expected at most {2**63 - 1}")
    return value


# Numbers and flags are strict: TOML `true` is not 1, and "2500" is not a number. An integer is
# still accepted where a float is expected.
Real = Annotated[float, Field(strict=True)]
Count = Annotated[int, Field(strict=True), AfterValidator(_int64)]
Flag = Annotated[bool, Field(strict=True)]
Vec3 = tuple[Real, Real, Real]
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)
    # (file name, TOML text) the values came from, set by config.load.parse_case, so that a
    # check made later (while building the scene) can still name the line of a key.
    _source: tuple[str, str] | None = PrivateAttr(None)


def _default_tag(data, field: str, tag: str, default: str):
    """Fill in the tag of a tagged union given as a table without it (its declared default)."""
    if isinstance(data, dict) and isinstance(data.get(field), dict) and tag not in data[field]:
        data = {**data, field: {tag: default, **data[field]}}
    return data
