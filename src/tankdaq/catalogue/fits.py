"""Every fit of a decay kept, and the one that is the lab's number: its reference fit.

A trial fit (a GA, an equation-error fit, a pooled ``--joint`` fit) must never replace the number a lab
reports, so a fit is added to ``fits`` and never written over another. The decay's reference fit is
chosen by a rule (``rank``): the fit a guided session accepted, else the first complete output-error fit
of a model chosen by the data, else the first fit; a decay that did not end whole (``records.DecayEnd``)
gets none by default. Only ``set_reference`` (``tankdaq runs --set-reference FIT``) changes it otherwise.
The decay row keeps a copy of its reference fit's numbers, so every query reads reference fits.
"""

from __future__ import annotations

import getpass
import math
import shlex
import socket
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import sqlalchemy as sa

from .._version import __version__
from ..records import DecayEnd
from .database import BadCatalogueQuery, Catalogue, in_batches
from .schema import REFERENCE_COPY, FitMethod, FitSource, budgets, decays, fits, utc_now

__all__ = ["FitMethod", "FitSource", "add_fits", "choose_reference", "fits_of", "set_reference"]


def provenance() -> dict[str, Any]:
    """Who made a fit, where, with which tankdaq and command (a catalogue URL in it is left out: it may
    hold a password)."""
    try:
        user: str | None = getpass.getuser()
    except (OSError, KeyError, ImportError):  # no login name (a container's uid without a passwd entry)
        user = None
    return {
        "software_version": __version__,
        "host": socket.gethostname(),
        "user_name": user,
        "command": command_line(sys.argv),
        "created_utc": utc_now(),
    }


def command_line(argv: Sequence[str]) -> str:
    """The command as typed, with the value of ``--catalogue`` and any URL replaced by ``CATALOGUE``."""
    words = []
    after_option = False
    for word in argv:
        if after_option or "://" in word:
            word = "CATALOGUE"
        elif word.startswith("--catalogue="):
            word = "--catalogue=CATALOGUE"
        after_option = word == "--catalogue"
        words.append(word)
    return shlex.join(words)


def _complete(fit: Mapping[str, Any]) -> bool:
    values = [entry.get("value") for entry in (fit.get("coefficients") or {}).values()]
    return bool(values) and all(isinstance(v, int | float) and math.isfinite(v) for v in values)


def rank(fit: Mapping[str, Any]) -> int:
    """0: a guided session's accepted fit; 1: a complete output-error fit of a model the data chose (of
    this decay's condition: not a ``--joint`` pool); 2: any other. The reference is the lowest rank,
    the first fit of it: so a later fit of the same or a lower rank never replaces it."""
    if fit["source"] == FitSource.SESSION:
        return 0
    if (
        fit["method"] == FitMethod.OUTPUT_ERROR
        and fit["model_by_data"]
        and fit["source"] != FitSource.IDENTIFY_JOINT
        and _complete(fit)
    ):
        return 1
    return 2


def whole(ended: str | None, complete: bool) -> bool:
    """A decay whose file holds all of it (not said: a lab's own file, taken as whole)."""
    if not complete:
        return False
    if ended is None:
        return True
    try:
        return DecayEnd(ended).whole
    except ValueError:
        return False


def add_fits(connection: sa.Connection, found: Iterable[tuple[Mapping[str, Any], Mapping[str, Any]]]) -> None:
    """Each (decay row: ``id``, ``sha256``, ``path``; fit) kept; a fit stored in a file (``record``,
    ``session``) once per bytes. Then each decay's reference is chosen again (``choose_reference``)."""
    touched: set[int] = set()
    for decay, fit in found:
        if fit["source"] in (FitSource.RECORD, FitSource.SESSION):
            there = sa.select(fits.c.id).where(
                fits.c.sha256 == decay["sha256"], fits.c.source == fit["source"]
            )
            if connection.execute(there.limit(1)).first() is not None:
                continue
        values = {
            k: v for k, v in fit.items() if k in fits.c and k not in ("id", "decay_id", "sha256", "path")
        }
        kept = connection.execute(
            fits.insert().values(decay_id=decay["id"], sha256=decay["sha256"], path=decay["path"], **values)
        )
        add_budget(connection, int(kept.inserted_primary_key[0]), fit.get("budget") or ())  # type: ignore[index]
        touched.add(int(decay["id"]))
    for decay_id in sorted(touched):
        choose_reference(connection, decay_id)


def add_budget(connection: sa.Connection, fit_id: int, found: Iterable[Mapping[str, Any]]) -> None:
    """A fit's uncertainty budget (``Budget.as_dict``s) as ``budgets`` rows, one per quantity and source."""
    rows = [
        {"fit_id": fit_id, "quantity": b["quantity"], "quantity_key": b["key"], "unit": b["unit"]}
        | {"value": b["value"], "combined_u": b["combined_u"], "expanded_u": b["expanded_u"]}
        | {"coverage_factor": b["coverage_factor"], "u_unit": r["unit"]}
        | {key: r[key] for key in ("source", "kind", "u", "sensitivity", "contribution", "share")}
        for b in found
        for r in b["rows"]
    ]
    if rows:
        connection.execute(budgets.insert(), rows)


def choose_reference(connection: sa.Connection, decay_id: int) -> None:
    """The decay's reference fit by ``rank`` among the fits of its bytes (one the lab chose stays while
    its bytes are the row's); none for a decay that did not end whole. Its numbers copied to the row."""
    row = connection.execute(sa.select(decays).where(decays.c.id == decay_id)).first()
    if row is None:
        return
    candidates = [
        dict(f._mapping)
        for f in connection.execute(
            sa.select(fits)
            .where(fits.c.decay_id == decay_id, fits.c.sha256 == row.sha256)
            .order_by(fits.c.id)
        )
    ]
    if row.reference_chosen and any(f["id"] == row.reference_fit_id for f in candidates):
        return
    best = None
    if whole(row.ended, bool(row.complete)) and candidates:
        best = min(candidates, key=lambda f: (rank(f), f["id"]))
    _copy_reference(connection, decay_id, best, chosen=False)


def _copy_reference(
    connection: sa.Connection, decay_id: int, fit: Mapping[str, Any] | None, chosen: bool
) -> None:
    values: dict[str, Any] = {column: None for column in REFERENCE_COPY.values()}
    if fit is not None:
        values = {column: fit[name] for name, column in REFERENCE_COPY.items()}
    values |= {"reference_fit_id": None if fit is None else fit["id"], "reference_chosen": chosen}
    connection.execute(decays.update().where(decays.c.id == decay_id).values(**values))


def set_reference(fit_id: int, catalogue: str | None = None) -> str:
    """Make fit ``fit_id`` (an ``id`` of ``runs --fits all``) its decay's reference fit: the lab's choice,
    which no later fit or rule changes. Returns the line that says what it replaced. ``catalogue``: a
    URL or path (default: as the CLI)."""
    from ..api.arguments import run_filters, whole
    from .database import open_catalogue, read_catalogue, resolve_url

    fit_id = whole(fit_id, "fit_id", 1, 2**63 - 1)
    _, catalogue, _ = run_filters({}, catalogue, False)
    url = resolve_url(catalogue)
    if url is None:
        raise BadCatalogueQuery("the catalogue is switched off (none): give a catalogue")
    read_catalogue(url).close()  # one that is not there, or not tankdaq's, is refused, never made
    with open_catalogue(url) as opened:
        return reference_to(opened, fit_id)


def reference_to(catalogue: Catalogue, fit_id: int) -> str:
    """Make fit ``fit_id`` its decay's reference (the lab's choice: no later fit or rule changes it);
    returns the line that says what it replaced. A fit of bytes the row no longer holds is refused."""
    with catalogue.engine.begin() as connection:
        fit = connection.execute(sa.select(fits).where(fits.c.id == fit_id)).first()
        if fit is None:
            raise BadCatalogueQuery(
                f"--set-reference (fit_id) {fit_id}: no such fit; `tankdaq runs --fits all` lists them"
            )
        row = connection.execute(sa.select(decays).where(decays.c.id == fit.decay_id)).first()
        if row is None or row.sha256 != fit.sha256:
            raise BadCatalogueQuery(
                f"--set-reference (fit_id) {fit_id}: that fit read bytes its file no longer holds; "
                "fit the file again"
            )
        before = connection.execute(sa.select(fits).where(fits.c.id == row.reference_fit_id)).first()
        _copy_reference(connection, row.id, dict(fit._mapping), chosen=True)
    replaced = "had none"
    if before is not None:
        replaced = f"replaces fit {before.id} ({describe_fit(dict(before._mapping))})"
    return f"{row.path}: reference fit {fit_id} ({describe_fit(dict(fit._mapping))}); {replaced}"


def describe_fit(fit: Mapping[str, Any]) -> str:
    """A fit as a line names it: its method, model and the command that made it."""
    return f"{fit['method']} {fit['model'] or ''}, {fit['source']}".replace(" ,", ",")


#: What ``runs --fits all`` shows of each fit, after its decay's condition.
FIT_LISTING = (
    "id", "reference", "source", "method", "model", "model_by_data", "natural_period_s", "r2_angle",
    "coefficients", "b_eq_per_s", "b44_hat", "warnings", "settings", "software_version", "host",
    "user_name", "created_utc", "command",
)  # fmt: skip


def fits_of(catalogue: Catalogue, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Every fit of the decays ``rows`` (of the bytes each row holds), oldest first, each with
    ``reference`` (True for the row's reference fit)."""
    by_id = {row["id"]: row for row in rows}
    found: list[dict[str, Any]] = []
    with catalogue.reading() as connection:
        for batch in in_batches(list(by_id)):
            statement = sa.select(fits).where(fits.c.decay_id.in_(batch)).order_by(fits.c.id)
            for fit in connection.execute(statement):
                row = by_id[fit.decay_id]
                if fit.sha256 == row["sha256"]:
                    entry = dict(fit._mapping) | {"reference": fit.id == row.get("reference_fit_id")}
                    found.append({"decay_path": row["path"], **{k: entry.get(k) for k in FIT_LISTING}})
    return sorted(found, key=lambda f: f["id"])
