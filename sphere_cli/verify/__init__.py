"""Verification: cases with analytic or published references, run over resolution ladders
(error against run time, observed order of convergence), and the stability suite."""

from .registry import REGISTRY, Outcome, Tolerance, VerificationCase, cases
from .runner import observed_order, run_case
from .suite import all_names, run_verification

__all__ = [
    "REGISTRY",
    "Outcome",
    "Tolerance",
    "VerificationCase",
    "all_names",
    "cases",
    "observed_order",
    "run_case",
    "run_verification",
]
