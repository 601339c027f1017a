"""The documentation cannot drift from the code: the committed case reference is exactly what the
generator writes, it names every key of the JSON schema, and every example case validates."""

from __future__ import annotations

from pathlib import Path

import pytest

from sphere_cli import api
from sphere_cli.config import reference as docgen

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "docs" / "case-reference.md"
CONFIGS = sorted((ROOT / "configs").glob("*.toml"))


def schema_paths(schema: dict) -> set[str]:
    """Every key of the case schema as a TOML path (`walls[].face`), found by walking the JSON
    schema (independently of the generator, which walks the pydantic models)."""
    defs = schema.get("$defs", {})
    paths: set[str] = set()

    def resolve(node: dict) -> dict:
        while "$ref" in node:
            node = defs[node["$ref"].split("/")[-1]]
        return node

    def objects(node: dict):
        """The object schemas a node can be: itself, its union members, its list items."""
        node = resolve(node)
        if node.get("type") == "object" and "properties" in node:
            yield node, ""
        for key in ("anyOf", "oneOf"):
            for member in node.get(key, []):
                yield from objects(member)
        if node.get("type") == "array" and isinstance(node.get("items"), dict):
            for obj, _ in objects(node["items"]):
                yield obj, "[]"

    def walk(node: dict, prefix: str) -> None:
        for obj, suffix in objects(node):
            for name, prop in obj["properties"].items():
                path = f"{prefix}{suffix}.{name}" if prefix else name
                paths.add(path)
                walk(prop, path)

    walk(schema, "")
    return paths


def test_reference_is_up_to_date():
    assert REFERENCE.is_file(), "docs/case-reference.md is missing: run `make docs`"
    assert REFERENCE.read_text(encoding="utf-8") == docgen.generate(), (
        "docs/case-reference.md is out of date with sphere_cli/config/schema.py: run `make docs`"
    )


def test_every_schema_key_is_documented():
    text = docgen.generate()
    paths = schema_paths(api.schema())
    assert {
        "simulation.dt",
        "particles.radius.sigma",
        "contact.restitution",
        "walls[].face",
        "output.checkpoints.keep",
    } <= paths  # the walk itself reaches nested and tagged keys
    leaves = {p for p in paths if not any(q.startswith(p + ".") or q.startswith(p + "[].") for q in paths)}
    missing = sorted(p for p in leaves if f"`{p}`" not in text)
    assert not missing, f"keys missing from the case reference: {missing}"
    tables = sorted(p for p in paths - leaves if f"`[{p}]`" not in text and f"`[[{p}]]`" not in text)
    assert not tables, f"tables missing from the case reference: {tables}"


def discriminated_unions(node, found=None) -> list[tuple[str, list[str]]]:
    """(tag key, tag values) of every tagged union anywhere in the JSON schema."""
    found = [] if found is None else found
    if isinstance(node, dict):
        if isinstance(node.get("discriminator"), dict):
            found.append((node["discriminator"]["propertyName"], sorted(node["discriminator"]["mapping"])))
        for value in node.values():
            discriminated_unions(value, found)
    elif isinstance(node, list):
        for value in node:
            discriminated_unions(value, found)
    return found


def test_every_tagged_variant_is_documented():
    text = docgen.generate()
    unions = discriminated_unions(api.schema())
    assert {tag for tag, _ in unions} >= {"distribution", "method", "model"}
    missing = [
        f'{tag} = "{value}"'
        for tag, values in unions
        for value in values
        if f'`{tag} = "{value}"`' not in text
    ]
    assert not missing, f"variants without their own section in the case reference: {missing}"


def test_units_are_shown():
    text = docgen.generate()
    row = next(line for line in text.splitlines() if line.startswith("| `domain.gravity` |"))
    assert "| m/s^2 |" in row
    row = next(line for line in text.splitlines() if line.startswith("| `particles.density` |"))
    assert "| kg/m^3 |" in row and "| > 0 |" in row
    row = next(line for line in text.splitlines() if line.startswith("| `simulation.duration` |"))
    assert "| s |" in row and "| > 0 |" in row and "*required*" in row


def test_check_mode(tmp_path, capsys):
    target = tmp_path / "ref.md"
    assert docgen.main([str(target)]) == 0
    assert docgen.main(["--check", str(target)]) == 0
    target.write_text(target.read_text() + "stale\n")
    assert docgen.main(["--check", str(target)]) == 1
    assert docgen.main(["--check", str(tmp_path / "absent.md")]) == 1
    assert "make docs" in capsys.readouterr().err


@pytest.mark.parametrize("case", CONFIGS, ids=[p.name for p in CONFIGS])
def test_example_case_validates(case):
    resolved = api.validate(case)
    assert resolved["simulation"]["duration"] > 0


def test_there_are_example_cases():
    assert CONFIGS, "configs/ holds no example case"
