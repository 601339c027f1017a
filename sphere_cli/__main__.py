"""`python -m sphere_cli`: the `sphere` command through a given interpreter (sweep members
start this way: sphere_cli/sweep.py)."""

from .cli import main

main()
