"""The report at the end of a guided session: ``tankdaq campaign``'s report of the accepted decays (the same
pipeline, ``tankdaq.campaign``, its IMO table of Bertin's N included), plus each coefficient's
repeat-to-repeat spread for the conditions with two or more repeats, and each condition's uncertainty
budget (``ident.budget``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..config.hulls import format_draft

#: the report's folder inside the session's
REPORT_DIR = "report"


def write_session_report(files: list[Path], folder: Path, model: str, hull: str) -> list[Path]:
    """``tankdaq campaign``'s report of ``files`` (``tankdaq.campaign``, in this process: the session's
    device may still be streaming), plus each coefficient's repeat-to-repeat spread
    (``repeat_spread.csv`` and a section of campaign.md) for the conditions with two or more repeats."""
    from ..api.campaigns import campaign

    found = campaign(files, model, hulls=[hull], report=folder, keep_fits=True)
    written = list(found.report_files)
    fitted = {r.key: (r.runs, tuple(r.fit.terms_)) for r in found.results if r.fit is not None}
    spread = repeat_spreads(fitted)
    if spread:
        written.append(_write_spread(spread, folder))
    budgets = [(r.key.label, r.budget) for r in found.results if r.budget]
    if budgets:
        written.append(_write_budgets(budgets, folder))
    return written


def repeat_spreads(groups: dict[Any, tuple[list[Any], tuple[str, ...]]]) -> list[dict[str, Any]]:
    """Per condition with repeats: each coefficient fitted on each repeat alone (with the terms of the
    condition's fit, the model the campaign chose), their mean and spread."""
    from functools import partial

    from ..ident.intervals import repeat_spread
    from ..ident.output_error import OutputErrorFit

    rows = []
    for key, (runs, model) in groups.items():
        if len(runs) < 2:
            continue
        summary = repeat_spread(partial(OutputErrorFit, model), runs)
        terms = list(summary.std)
        row: dict[str, Any] = {"hull": key.hull, "axis": key.axis, "draft": format_draft(key.draft),
                               "angle_deg": key.angle_deg, "repeats": len(runs)}  # fmt: skip
        for i, term in enumerate(terms):
            values = summary.samples[:, i]
            row[f"{term}_mean"] = float(values.mean())
            row[f"{term}_repeat_sd"] = float(values.std(ddof=1))
        rows.append(row)
    return rows


def _write_spread(rows: list[dict[str, Any]], folder: Path) -> Path:
    from ..ident.interval_labels import SCATTER_STD
    from ..store.safe_write import write_rows

    path = write_rows(rows, folder / "repeat_spread.csv")  # a new file, as the rest of the report
    columns = list(dict.fromkeys(k for row in rows for k in row))
    terms = [c[: -len("_mean")] for c in columns if c.endswith("_mean")]
    lines = [
        "\n## Repeat-to-repeat spread\n",
        f"Each repeat fitted alone; the mean {SCATTER_STD}: the repeats' sample standard deviation.\n",
        "| draft | angle deg | repeats | " + " | ".join(terms) + " |",
        "|" + "---|" * (3 + len(terms)),
    ]
    for row in rows:
        cells = [row["draft"], f"{row['angle_deg']:g}", str(row["repeats"])]
        cells += [f"{row[t + '_mean']:.4g} ± {row[t + '_repeat_sd']:.2g}" for t in terms]
        lines.append("| " + " | ".join(cells) + " |")
    with (folder / "campaign.md").open("a") as fh:
        fh.write("\n".join(lines) + "\n")
    return path


def _write_budgets(budgets: list[tuple[str, tuple[dict[str, Any], ...]]], folder: Path) -> Path:
    """Each condition's uncertainty budget: every row in ``budget.csv``, the tables in campaign.md."""
    from ..api.identification import budget_table
    from ..ident.budget import text_table
    from ..store.safe_write import write_rows

    rows = [{str(k): v for k, v in row.items()} for row in budget_table(budgets).to_dict("records")]
    path = write_rows(rows, folder / "budget.csv")
    lines = ["\n## Uncertainty budget\n", "Type A from each condition's repeats (ISO GUM; docs/models.md).\n"]
    for label, found in budgets:
        lines += [f"\n### {label}\n", "```", *text_table(found), "```"]
    with (folder / "campaign.md").open("a") as fh:
        fh.write("\n".join(lines) + "\n")
    return path
