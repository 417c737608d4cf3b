"""Every test's run catalogue is a temporary file: no test ever writes the user's own catalogue."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True, scope="session")
def _catalogue_in_a_temp_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """``TANKDAQ_CATALOGUE`` for the session (and every process a test starts inherits it)."""
    patch = pytest.MonkeyPatch()
    patch.setenv("TANKDAQ_CATALOGUE", str(tmp_path_factory.mktemp("catalogue") / "catalogue.sqlite"))
    yield
    patch.undo()
