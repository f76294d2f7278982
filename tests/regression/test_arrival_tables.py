"""Every built-in scene's arrivals (direct, specular, edge) against the stored tables.

The tables were written by ``tests/regression/arrival_tables.py`` from the fast engine. A
difference means the physics or the numerics changed: if on purpose, regenerate them and say
why in the commit; if not, it is a regression.
"""

from __future__ import annotations

import pytest

from arrival_tables import solve_arrivals, stored_arrivals, table_names
from support.parity import assert_rows_match

REGRESSION_AMPLITUDE_RTOL = 1e-7
"""Stored amplitudes hold within 1e-7 relative (1e-6 dB): room for a different summation order
of an edge's elements (their sum is what an arrival's amplitude is) across numpy versions and
CPUs, far below any change of the physics worth a look."""


@pytest.mark.parametrize("name", table_names())
def test_fast_engine_reproduces_the_stored_arrivals(name: str) -> None:
    assert_rows_match(solve_arrivals(name, "fast"), stored_arrivals(name), amplitude_rtol=REGRESSION_AMPLITUDE_RTOL,
                      label=name)


@pytest.mark.parametrize("name", [n for n in table_names() if not n.startswith("thesis-tank")])
def test_reference_engine_reproduces_the_stored_arrivals(name: str) -> None:
    assert_rows_match(solve_arrivals(name, "reference"), stored_arrivals(name),
                      amplitude_rtol=REGRESSION_AMPLITUDE_RTOL, label=name)


@pytest.mark.slow
def test_reference_engine_reproduces_the_thesis_tank_arrivals() -> None:
    assert_rows_match(solve_arrivals("thesis-tank", "reference"), stored_arrivals("thesis-tank"),
                      amplitude_rtol=REGRESSION_AMPLITUDE_RTOL, label="thesis-tank")
