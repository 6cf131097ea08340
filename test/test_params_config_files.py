"""``config/rca_<mode>.yaml`` state each mode's parameter defaults: they must stay the
defaults of :mod:`ads_rca.params` (a file that drifted would silently change the nodes'
verdicts when passed as ``--params-file``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from ads_rca.foundation.yaml_files import load_config
from ads_rca.oracles.semantics import semantics_for
from ads_rca.params import SEMANTICS, make_params

CONFIG = Path(__file__).resolve().parent.parent / "config"


def typed(values: dict[str, Any]) -> dict[str, tuple[str, Any]]:
    """Values with their types (``1`` in a file is not the float parameter ``1.0``)."""
    return {name: (type(value).__name__, value) for name, value in values.items()}


@pytest.mark.parametrize("semantics", SEMANTICS)
def test_the_mode_config_file_holds_exactly_the_mode_defaults(semantics: str) -> None:
    stated = load_config(CONFIG / f"rca_{semantics}.yaml")
    defaults = {"semantics": semantics, **semantics_for(semantics).used(make_params(semantics))}
    assert typed(stated) == typed(defaults)
    assert list(stated) == list(defaults)  # same order as Semantics.parameters
