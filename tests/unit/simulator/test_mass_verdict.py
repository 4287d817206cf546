"""A mass the team cannot back is not published: generated load 47 on the noise benchmark's
floor (10.5 kg, J = 8.5 kg m² under three robots whose centroid is 1.3 m from its COM,
μ = 1.65 %) leaves Step 5 with ``ẑ_C`` 30 cm off, its standard deviation 28 cm. Step 7's push,
meant to act through that COM, turns the load, and the COM's displacement the mass fit reads is
off by the offset's error turned. Its ``m̂`` was 37 % off behind a published 95 % interval of
±9.5 %: now the mass fit's uncertainty carries the offset's (``MassFit._offset_variance``), no
robot publishes a mass known to worse than 25 %, nor one measured while the load turned more
than ``SWUNG_TURN`` back under the push (0.66 rad, once the push went along and across ``f``: its
``m̂`` was 56 % off), and the run ends with that verdict. Its ``p_C − p_Ci`` was 396 mm off on
every robot, outside every published 95 % ellipse (standard deviations of 105–108 mm): the
swing that says the COM was off now withholds it too."""

from __future__ import annotations

from types import SimpleNamespace

from simulator.inprocess import run_inprocess
from simulator.lockstep import MASS_NOT_DETERMINED, Verdict, mass_verdict
from simulator.results import intervals, results_dict
from tests.helpers.floor import generated_on_floor


def test_a_mass_known_too_roughly_gets_a_verdict_not_a_number() -> None:
    scenario, _, _ = generated_on_floor(47, max_time_s=40.0)
    outcome = run_inprocess(scenario)
    final = outcome.final
    if outcome.converged:  # then every robot's interval holds the truth
        for est in final.estimates.values():
            assert abs(est.mass - final.truth.mass) <= 1.96 * est.mass_std, est
        return
    assert outcome.reason == MASS_NOT_DETERMINED, outcome.detail
    assert "worse than 25 %, or measured it while the load turned" in outcome.detail
    assert all(est.mass is None for est in final.estimates.values())
    assert results_dict(outcome)["reason"] == MASS_NOT_DETERMINED
    for robot, est in final.estimates.items():  # no COM published, or one that holds the truth
        assert est.contact_to_com is None or intervals(outcome, robot)["contact_to_com"][1], est
    if any(est.contact_to_com is None for est in final.estimates.values()):
        assert "nor is the COM by robot(s)" in outcome.detail


def test_the_verdict_names_the_robots_without_a_mass() -> None:
    com = (0.1, 0.2)
    known = {1: SimpleNamespace(mass=5.0, contact_to_com=com), 2: SimpleNamespace(mass=5.1)}
    assert mass_verdict(Verdict(), known, 12.0) == Verdict()
    unknown = {
        robot: SimpleNamespace(mass=m, contact_to_com=com)
        for robot, m in ((1, 5.0), (2, None), (3, None))
    }
    found = mass_verdict(Verdict(), unknown, 12.0)
    assert found.reason == MASS_NOT_DETERMINED
    assert "robot(s) [2, 3]" in found.detail and "t = 12.00 s" in found.detail
    assert "COM" not in found.detail.split(":")[-1]
    unknown[3].contact_to_com = None  # swung: no COM either
    found = mass_verdict(Verdict(), unknown, 12.0)
    assert found.detail.endswith(
        "nor is the COM by robot(s) [3]: the load turned under the push, so their COM was off"
    )
    halted = Verdict("team halted", "the team halted")  # a verdict already given stands
    assert mass_verdict(halted, unknown, 12.0) == halted
