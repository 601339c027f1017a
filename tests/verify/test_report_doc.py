"""docs/verification.md is generated from a full `sphere verify` run (`make verify`): it must
cover every registered case, link plots that exist, and state the machine and thread count."""

from __future__ import annotations

import re
from pathlib import Path

from sphere_cli.verify import all_names

DOC = Path(__file__).resolve().parents[2] / "docs" / "verification.md"


def test_report_covers_every_case():
    text = DOC.read_text(encoding="utf-8")
    missing = [name for name in all_names() if f"`{name}`" not in text]
    assert not missing, f"docs/verification.md lacks {missing}: run `make verify`"


def test_report_plots_exist_and_are_small():
    text = DOC.read_text(encoding="utf-8")
    plots = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", text)
    assert plots
    for plot in plots:
        path = DOC.parent / plot
        assert path.is_file(), plot
        assert path.stat().st_size < 200_000, plot


def test_report_states_machine_threads_and_date():
    text = DOC.read_text(encoding="utf-8")
    assert re.search(r"- Machine: .+, \d+ cores", text)
    assert re.search(r"- Numba threads: \d+", text)
    assert re.search(r"- Date: \d{4}-\d{2}-\d{2}", text)
