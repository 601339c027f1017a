"""Outputs of `sphere verify`: verify.json (machine-readable, comparable run to run), one
Markdown table per case, the stability table, and PNG plots (error vs resolution with reference
slopes, error vs wall time) when matplotlib is installed (`pip install sphere-cli[plot]`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..io.json_text import json_text

PLOT_HINT = "plots need matplotlib: pip install 'sphere-cli[plot]' (tables and verify.json are written)"
SCHEMA = "sphere-verify/1"


def write_json(report: dict, path: Path) -> None:
    """verify.json, strict JSON (a value NaN or infinite is null: io/json_text.py)."""
    path.write_text(json_text(report) + "\n", encoding="utf-8")


def fmt(value, digits: int = 3) -> str:
    """A number for a table: 3 significant digits, '-' for missing, 0 as 0."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if value == 0:
        return "0"
    if not math.isfinite(value):
        return str(value)
    return f"{value:.{digits}g}"


def _mark(passed: bool) -> str:
    return "pass" if passed else "**FAIL**"


def case_markdown(record: dict, plot: str | None = None, heading: str = "##") -> str:
    """The Markdown section of one verification case: reference, set-up, table, orders, checks."""
    rows = record["rows"]
    metrics = list(rows[0]["errors"]) if rows else []
    drifts = sorted({k for r in rows for k in r["drift"]})
    lines = [
        f"{heading} `{record['name']}`: {record['title']} ({_mark(record['passed'])})",
        "",
        f"- Reference: {record['reference']}.",
        f"- Set-up: {record['description']}.",
    ]
    formal = record["formal_order"]
    order_text = "exact (no truncation error)" if formal is None else f"{formal:g}"
    if record["min_order"] is not None:
        order_text += f", required >= {record['min_order']:g} for " + ", ".join(record["order_metrics"])
    note = record["order_note"]
    lines.append(f"- Formal order: {order_text}. {note[:1].upper() + note[1:]}.")
    for t in record["tolerances"]:
        bound = f"{t['bound']:g}" if t["bound"] is not None else f"{t['ulps_per_step']:g} ulp x steps"
        where = f" at >= {t['min_resolution']:g} {record['resolution']}" if t["min_resolution"] else ""
        lines.append(f"- Tolerance: {t['metric']} <= {bound}{where} ({t['source']}).")
    if record.get("error"):
        lines += ["", f"The case failed to run: `{record['error']}`"]
    labels = record["error_labels"]
    if metrics:
        lines += ["", "Errors: " + "; ".join(f"{m} = {labels.get(m, m)}" for m in metrics) + ".", ""]
        head = (
            [record["resolution"], "dt [s]", "steps"]
            + metrics
            + [f"{d} drift" for d in drifts]
            + ["wall [s] (median)", "stepping [s]", f"per {rows[0].get('work_unit', 'particle-step')} [us]"]
        )
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "---:|" * len(head))
        for r in rows:
            per = r["time_per_work_s"]
            cells = (
                [fmt(r["resolution"]), fmt(r["dt"]), str(r["steps"])]
                + [fmt(r["errors"][m]) for m in metrics]
                + [fmt(r["drift"].get(d)) for d in drifts]
                + [fmt(r["wall_s"]), fmt(r["step_s"]), fmt(None if per is None else per * 1e6)]
            )
            lines.append("| " + " | ".join(cells) + " |")
        orders = ", ".join(f"{m} {fmt(record['orders'].get(m), 3)}" for m in metrics)
        lines += ["", f"Observed order (least-squares slope over the ladder): {orders}."]
    if "first_call_s" in record:
        lines.append(
            f"First call {record['first_call_s']:.3g} s (kernel compile or cache load: "
            f"{record.get('compile_s', 0.0):.3g} s, reported apart from the timings); each row is the "
            f"median of {record['repeats']} runs."
        )
    elif record["rows"]:
        lines.append(
            "One run per resolution (a costly case), its kernel compilation in the first row's time."
        )
    lines += ["", "| check | result | detail |", "|---|---|---|"]
    for c in record["checks"]:
        lines.append(f"| {c['check']} | {_mark(c['passed'])} | {c['detail']} |")
    if plot:
        lines += ["", f"![{record['name']}]({plot})"]
    return "\n".join(lines) + "\n"


def stability_markdown(records: list[dict], heading: str = "##") -> str:
    lines = [
        f"{heading} Stability suite",
        "",
        "What the program did with stiff and extreme input, and the largest stable dt found by "
        "bisection, as a multiple of the limit the builder enforces (>= 1: every accepted dt is "
        "stable).",
        "",
        "| case | expected | did | exit | limit [s] | largest stable dt / limit | result |",
        "|---|---|---|---:|---:|---:|---|",
    ]
    for r in records:
        lines.append(
            f"| `{r['name']}`: {r['title']} | {r['expected']} | {r['action']} | {fmt(r.get('exit_code'))} | "
            f"{fmt(r.get('theory_dt_s'))} | {fmt(r.get('largest_stable_ratio'), 4)} | {_mark(r['passed'])} |"
        )
    for r in records:
        lines += ["", f"**`{r['name']}`** ({_mark(r['passed'])}). {r['detail']}"]
        if r.get("theory"):
            lines.append(f"Theory: {r['theory']}.")
        lines += ["", "| check | result | detail |", "|---|---|---|"]
        for c in r["checks"]:
            detail = str(c["detail"]).replace("|", "/").replace("\n", " ")
            lines.append(f"| {c['check']} | {_mark(c['passed'])} | {detail} |")
    return "\n".join(lines) + "\n"


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def plots_available() -> bool:
    return _pyplot() is not None


def plot_case(record: dict, path: Path) -> bool:
    """Two panels: error vs resolution (log-log, with the formal order's slope drawn through the
    coarsest point of each checked metric) and error vs the median time spent stepping (the
    scene build, a few ms, is left out). False without matplotlib or data."""
    plt = _pyplot()
    rows = record["rows"]
    if plt is None or not rows:
        return False
    res = np.array([r["resolution"] for r in rows], dtype=float)
    wall = np.array([r["step_s"] for r in rows], dtype=float)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.0, 3.4))
    formal = record["formal_order"]
    for k, metric in enumerate(rows[0]["errors"]):
        err = np.array([r["errors"][metric] for r in rows], dtype=float)
        ok = err > 0
        if not ok.any():
            continue
        order = record["orders"].get(metric)
        label = metric if order is None else f"{metric} (order {order:.2f})"
        color = f"C{k % 10}"
        ax1.loglog(res[ok], err[ok], "o-", color=color, label=label, ms=4)
        ax2.loglog(wall[ok], err[ok], "o-", color=color, label=metric, ms=4)
        if formal is not None and metric in record["order_metrics"] and ok.sum() >= 2:
            x0, y0 = res[ok][0], err[ok][0]
            xs = np.array([x0, res[ok][-1]])
            ax1.loglog(xs, y0 * (xs / x0) ** (-formal), ":", color=color, lw=1)
    if formal is not None:
        ax1.plot([], [], "k:", lw=1, label=f"slope -{formal:g} (formal)")
    ax1.set_xticks(res)
    ax1.set_xticklabels([f"{r:g}" for r in res], fontsize=7)
    ax1.xaxis.set_minor_formatter(plt.NullFormatter())
    ax1.set_xlabel(record["resolution"])
    ax1.set_ylabel("error")
    ax1.set_title("error vs resolution", fontsize=10)
    ax1.legend(fontsize=7)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.set_xlabel("time stepping per run [s] (median)")
    ax2.set_title("work-precision", fontsize=10)
    ax2.grid(True, which="both", alpha=0.3)
    fig.suptitle(record["name"], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return True


def plot_work_precision(records: list[dict], path: Path) -> bool:
    """All cases on one work-precision plot: the first checked metric of each against wall time."""
    plt = _pyplot()
    if plt is None:
        return False
    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    drawn = 0
    for k, record in enumerate(records):
        rows = record["rows"]
        if not rows:
            continue
        metric = (record["order_metrics"] or list(rows[0]["errors"]))[0]
        err = np.array([r["errors"][metric] for r in rows], dtype=float)
        wall = np.array([r["step_s"] for r in rows], dtype=float)
        ok = (err > 0) & (wall > 0)
        if ok.sum() == 0:
            continue
        ax.loglog(wall[ok], err[ok], "o-", ms=3, color=f"C{k % 10}", label=f"{record['name']}: {metric}")
        drawn += 1
    if not drawn:
        plt.close(fig)
        return False
    ax.set_xlabel("time stepping per run [s] (median)")
    ax.set_ylabel("error")
    ax.set_title("work-precision, all cases", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return True


def write_outputs(report: dict, out_dir: Path, plots: bool = True) -> list[str]:
    """verify.json, <case>.md for every case, stability.md, and the PNGs; returns notes for the
    user (e.g. that plots were skipped)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    notes = []
    can_plot = plots and plots_available()
    if plots and not can_plot:
        notes.append(PLOT_HINT)
    for record in report["cases"]:
        png = f"{record['name']}.png"
        drawn = can_plot and plot_case(record, out_dir / png)
        record["plot"] = png if drawn else None
        (out_dir / f"{record['name']}.md").write_text(
            case_markdown(record, png if drawn else None), encoding="utf-8"
        )
    if report["stability"]:
        (out_dir / "stability.md").write_text(stability_markdown(report["stability"]), encoding="utf-8")
    if can_plot and report["cases"]:
        report["work_precision_plot"] = (
            "work-precision.png"
            if plot_work_precision(report["cases"], out_dir / "work-precision.png")
            else None
        )
    report["notes"] = notes
    write_json(report, out_dir / "verify.json")
    return notes
