"""The contact laws, one file each, chosen by `[contact] model`."""

from __future__ import annotations

from .base import ContactLaw
from .hertz_mindlin import HertzMindlin
from .linear import Linear

LAWS: dict[str, ContactLaw] = {law.name: law for law in (Linear(), HertzMindlin())}
