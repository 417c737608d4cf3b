"""``tankdaq runs --compare A B``: two selections of catalogued decays side by side per condition (this
year's campaign against last year's), each a session, a plan or a ``--runs`` query; decays that ended
whole."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from .database import BadCatalogueQuery, Catalogue
from .query import RunQuery, decoded, flat, parse_runs, select_rows, whole_unless_asked
from .schema import decays

#: What ``compare`` groups by: the condition a lab compares across campaigns.
CONDITION = ("hull", "axis", "draft", "angle_nominal_deg")
COMPARED = ("natural_period_s", "b_eq_5deg_per_s", "b44_hat_5deg", "r2_angle")


def selection(catalogue: Catalogue, text: str) -> list[dict[str, Any]]:
    """One side of ``runs --compare``: a session id (or its first characters), a session folder, a
    plan name, or a ``--runs`` query."""
    if "=" in text:
        return select_rows(catalogue, whole_unless_asked(parse_runs(text)))
    folder = Path(text)
    if (folder / "session.jsonl").is_file():
        from .writing import session_id

        text = session_id(folder / "session.jsonl")
    statement = sa.select(decays).where(
        sa.or_(decays.c.session_id.startswith(text, autoescape=True), decays.c.plan == text),
        *whole_unless_asked(RunQuery()).conditions(),  # the decays kept, that ended whole
    )
    with catalogue.reading() as connection:
        rows = [decoded(dict(row._mapping)) for row in connection.execute(statement)]
    if not rows:
        raise BadCatalogueQuery(f"--compare {text!r}: no session, plan or query in the catalogue matches")
    return rows


def compare(first: list[dict[str, Any]], second: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Two selections side by side, per condition: how many decays, and the mean period, B_eq and B̂44
    at 5 deg and R² of each (``_a``, ``_b``), with B_eq's change in per cent."""

    def means(rows: list[dict[str, Any]]) -> dict[tuple[Any, ...], dict[str, Any]]:
        groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
        for row in map(flat, rows):
            groups.setdefault(tuple(row.get(k) for k in CONDITION), []).append(row)
        out = {}
        for key, group in groups.items():
            entry: dict[str, Any] = {"n": len(group)}
            for name in COMPARED:
                values = [float(r[name]) for r in group if r.get(name) is not None]
                entry[name] = sum(values) / len(values) if values else math.nan
            out[key] = entry
        return out

    a, b = means(first), means(second)
    table = []
    for key in sorted(set(a) | set(b), key=lambda k: tuple(str(v) for v in k)):
        row: dict[str, Any] = dict(zip(CONDITION, key, strict=True))
        for side, found in (("a", a.get(key)), ("b", b.get(key))):
            row[f"n_{side}"] = found["n"] if found else 0
            for name in COMPARED:
                row[f"{name}_{side}"] = found[name] if found else math.nan
        b_a, b_b = row["b_eq_5deg_per_s_a"], row["b_eq_5deg_per_s_b"]
        row["b_eq_5deg_change_pct"] = 100.0 * (b_b - b_a) / b_a if b_a else math.nan
        table.append(row)
    return table
