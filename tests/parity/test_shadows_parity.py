"""Shadowed rows on both engines: the same rows and, row for row, the same responses.

The shadow step is one engine-independent function applied to each engine's direct and specular
rows (whose points agree within 1e-9 m), so matching rows must carry equal responses: the same
labels and spans, transfer functions within 1e-9 relative."""

from __future__ import annotations

import numpy as np

from acoustisim.propagation import SolverConfig, prepare, solve
from support.parity import assert_rows_match, canonical_order


def test_engines_give_the_same_shadow_responses(thesis_tank) -> None:
    prepared = prepare(thesis_tank)
    config = SolverConfig(mechanisms=("direct", "specular"), amplitude_floor_db=None)
    sonars = [thesis_tank.sonar, thesis_tank.sonar.with_pose(position_m=(1.2, 1.35, 0.45), yaw_deg=-8.0)]
    f = np.linspace(250e3, 800e3, 12)
    for sonar in sonars:
        fast = solve(prepared, sonar, config)
        reference = solve(prepared, sonar, SolverConfig(mechanisms=("direct", "specular"), amplitude_floor_db=None,
                                                        backend="reference"))
        assert_rows_match(fast.rows, reference.rows, label="shadows")
        a = fast.rows[canonical_order(fast.rows)]
        e = reference.rows[canonical_order(reference.rows)]
        assert np.array_equal(a["response_id"] >= 0, e["response_id"] >= 0)
        shadowed = np.flatnonzero(a["response_id"] >= 0)
        assert shadowed.size > 50
        for i in shadowed:
            ra, re = fast.responses[a["response_id"][i]], reference.responses[e["response_id"][i]]
            assert ra.label == re.label
            assert np.allclose(ra.span_s, re.span_s, rtol=1e-9, atol=0.0)
            ha, he = ra.transfer(f, fast.sound_speed_m_s), re.transfer(f, reference.sound_speed_m_s)
            assert np.max(np.abs(ha - he) / np.abs(he)) < 1e-9
