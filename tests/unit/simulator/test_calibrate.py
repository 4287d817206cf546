"""``heft bench calibrate``: the needed factors from errors with known answers, the
calibrations from known intervals, simulated arcs, and the parser."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from agent.algorithm.robust.arc_fit import CORRELATION, DIRECTION_VARIANCE
from agent.algorithm.robust.least_squares import CORRELATION_TIME
from agent.algorithm.robust.uncertainty import PUBLISHED_VARIANCE, STEP5_COM_VARIANCE
from agent.platform.heft import main
from simulator.bench.arcs import LENGTHS_S, NOISES, ArcReading, fit_arc
from simulator.bench.calibrate import (
    CALIBRATIONS,
    CHI2_PLANAR,
    CHI2_SCALAR,
    Factor,
    arc_correlation,
    arc_ratios,
    command,
    correlation_time,
    covering,
    direction_variance,
    format_factors,
    planar_factor,
    published_variance,
    scalar_factor,
    seed_range,
    step5_com_variance,
)
from simulator.bench.noise import Interval, SeedResult

Z95 = math.sqrt(CHI2_SCALAR)


# ------------------------------------------------------------------------------ arithmetic
def test_a_scalar_needs_the_factor_that_puts_it_on_its_interval() -> None:
    assert scalar_factor(2.0 * Z95, 1.0) == pytest.approx(4.0)  # 2 σ-units out: 4 × σ²
    assert scalar_factor(-Z95, 4.0) == pytest.approx(0.25)
    # variance k·a + b: e² = χ² (k a + b) at k = 3
    assert scalar_factor(Z95 * math.sqrt(3 * 2.0 + 5.0), 2.0, 5.0) == pytest.approx(3.0)
    assert scalar_factor(Z95, 2.0, 1.0) == 0.0  # the unscaled share alone holds it
    assert scalar_factor(2.0 * Z95, 0.0, 1.0) == math.inf  # nothing to scale: never inside


def test_a_vector_needs_the_factor_that_puts_it_on_its_ellipse() -> None:
    assert planar_factor(0.0, 2.0 * CHI2_PLANAR) == pytest.approx(2.0)  # the whole C scaled
    assert planar_factor(CHI2_PLANAR / 2, CHI2_PLANAR) == pytest.approx(2.0)  # half the room
    assert planar_factor(CHI2_PLANAR + 0.1, 1.0) == math.inf  # out along the fixed axis
    assert planar_factor(1.0, 0.0) == 0.0


def test_the_factor_for_95_percent_is_the_order_statistic_that_covers_them() -> None:
    assert covering(list(range(1, 21))) == 19  # 19 of 20 at or below it
    assert covering(list(range(160, 0, -1))) == 152  # ⌈0.95 · 160⌉ = 152
    assert covering([3.0]) == 3.0 and math.isnan(covering([]))
    factor = Factor("x", 19.0, tuple(float(k) for k in range(1, 21)))
    assert factor.inside == 0.95 and factor.exact == 19.0
    assert Factor("x", 10.0, factor.needed).inside == 0.5


def test_errors_twice_as_wide_as_published_need_twice_the_factor() -> None:
    """Normal errors of variance ``2 k a`` published as ``k a``: the factor needed is ``2 k``;
    about 0.83 of them inside."""
    rng = np.random.default_rng(5)
    k, a = 1.5, 0.3
    errors = rng.normal(scale=math.sqrt(2 * k * a), size=20_000)
    factor = Factor("x", k, tuple(scalar_factor(e, a) for e in errors))
    assert factor.exact == pytest.approx(2 * k, rel=0.05)
    assert factor.inside == pytest.approx(0.834, abs=0.01)  # P(|z| < 1.96/√2)
    planar = rng.normal(scale=math.sqrt(2 * k * a), size=(20_000, 2))
    d2 = (planar**2).sum(axis=1) / (k * a)
    ellipse = Factor("x", k, tuple(planar_factor(0.0, k * d) for d in d2))
    assert ellipse.exact == pytest.approx(2 * k, rel=0.05)


# ------------------------------------------------------------------------------ calibrations
def _seed(seed: int, intervals: dict[str, list[Interval]]) -> SeedResult:
    return SeedResult(
        seed=seed,
        robust={},
        paper={},
        baseline={},
        robust_time_s=10.0,
        robust_done=True,
        paper_done=False,
        intervals=intervals,
    )


def test_published_variance_from_known_intervals() -> None:
    """Each estimate exactly on the boundary of the interval it needs: ``J`` with twice the
    published variance, ``contact_to_com`` with the published one, edges with half of it."""
    k_m, k_j, k_c, k_z = (
        PUBLISHED_VARIANCE[key] for key in ("mass", "moment", "contact_to_com", "relative")
    )
    var = 0.01
    e_j = Z95 * math.sqrt(2 * var)  # needs 2 × what was published: 2 k_j
    on_ellipse = math.sqrt(CHI2_PLANAR * var)  # d² = χ²: needs the published k
    result = _seed(
        3,
        {
            "mass": [Interval(1, (10.1,), (10.0,), (0.01 * k_m,))],  # 1 σ out of 1.96
            "moment": [Interval(1, (2.0 + e_j,), (2.0,), (var,))],
            # (just inside: on the boundary, rounding decides)
            "contact_to_com": [
                Interval(1, (on_ellipse * (1 - 1e-9), 0.0), (0.0, 0.0), (var, 0.0, var))
            ],
            "relative_positions": [
                Interval(1, (1.0, 0.0), (1.0 - on_ellipse, 0.0), (var, 0.0, var)),
                Interval(1, (0.0, 1.0), (0.0, 1.0), (var, 0.0, var)),  # no error
                Interval(2, (1.0, 0.0), (1.0, -0.5 * on_ellipse), (var, 0.0, var)),
            ],
        },
    )
    mass, moment, offset, edges, robots = published_variance([result])
    assert mass.factor == k_m and mass.needed == pytest.approx((1 / CHI2_SCALAR,))
    assert moment.factor == k_j and moment.exact == pytest.approx(2 * k_j)
    assert offset.exact == pytest.approx(k_c) and offset.inside == 1.0
    assert edges.needed == pytest.approx((k_z, 0.0, k_z / 4))
    assert robots.needed == pytest.approx((k_z, k_z / 4))  # robot 1: its worse edge


def test_step5_com_variance_scales_step_5s_whole_offset_covariance() -> None:
    """Step 5's offsets (``push_offset``) are published before the factor: one on the ellipse
    of three times its covariance needs 3, one without error 0; the published
    ``contact_to_com`` is not read."""
    var = 1e-4
    on_ellipse = math.sqrt(CHI2_PLANAR * 3 * var)
    result = _seed(
        0,
        {
            "push_offset": [
                Interval(1, (0.3, 0.1 + on_ellipse), (0.3, 0.1), (var, 0.0, var)),
                Interval(2, (0.3, 0.1), (0.3, 0.1), (var, 0.0, var)),
            ],
            "contact_to_com": [Interval(1, (1.0, 0.0), (0.0, 0.0), (var, 0.0, var))],
        },
    )
    (offset,) = step5_com_variance([result])
    assert offset.factor == STEP5_COM_VARIANCE
    assert offset.needed == pytest.approx((3.0, 0.0))


def test_direction_variance_scales_the_variance_across_the_edge_alone() -> None:
    """An edge along x published as ``R diag(A, D B)``: an error across it on the ellipse at
    ``2 D`` needs ``2 D``; the same error with a share along it needs more."""
    r = PUBLISHED_VARIANCE["relative"]
    a, b = 1e-6, 4e-6
    cov = (r * a, 0.0, r * DIRECTION_VARIANCE * b)
    across = math.sqrt(CHI2_PLANAR * 2 * DIRECTION_VARIANCE * b)
    along = math.sqrt(0.5 * CHI2_PLANAR * a)  # half the room along
    result = _seed(
        0,
        {
            "relative_positions": [
                Interval(1, (1.5, 0.0), (1.5, -across), cov),
                Interval(1, (1.5, 0.0), (1.5 - along, -across), cov),
            ]
        },
    )
    edges, robots = direction_variance([result])
    assert edges.factor == DIRECTION_VARIANCE
    assert edges.needed == pytest.approx((2 * DIRECTION_VARIANCE, 4 * DIRECTION_VARIANCE))
    assert robots.needed == pytest.approx((4 * DIRECTION_VARIANCE,))
    turned = _seed(0, {"relative_positions": [Interval(1, (0.0, 1.5), (across, 1.5), cov[::-1])]})
    assert direction_variance([turned])[0].needed == pytest.approx((2 * DIRECTION_VARIANCE,))


def test_correlation_time_scales_the_fits_share_alone() -> None:
    """``Ĵ``'s variance (without PUBLISHED_VARIANCE) is the fit's ``a`` and the rest ``b``:
    an error on the interval of ``3 a + b`` needs three times the correlation time."""
    a, b = 0.04, 0.05
    published = PUBLISHED_VARIANCE["moment"] * (a + b)
    e = Z95 * math.sqrt(3 * a + b)
    mass_e = Z95 * math.sqrt(0.5 * 0.01 + 0.02)
    result = _seed(
        0,
        {
            "moment": [Interval(1, (5.0 + e,), (5.0,), (published,), math.sqrt(a))],
            "own_mass": [Interval(1, (10.0 - mass_e,), (10.0,), (0.03,), 0.1)],
        },
    )
    moment, mass = correlation_time([result])
    assert moment.factor == CORRELATION_TIME and moment.unit == " s"
    assert moment.needed == pytest.approx((3 * CORRELATION_TIME,))
    assert mass.factor == 1.0 and mass.needed == pytest.approx((0.5,))


# ------------------------------------------------------------------------------ arcs
def test_simulated_arcs_are_read_at_each_length_and_fit_their_truth() -> None:
    readings = fit_arc(NOISES[0], seed=1)
    assert [r.seconds for r in readings] == list(LENGTHS_S)
    for r in readings:
        assert abs(r.radius_error) < 0.01 and math.hypot(*r.centre_error) < 0.01
        assert r.radius_variance > 0.0 and r.centre_covariance[0] > 0.0
    noiseless = fit_arc(0.0, seed=1)[-1]
    assert abs(noiseless.radius_error) < 1e-4 and math.hypot(*noiseless.centre_error) < 1e-4
    radius, centre = arc_correlation(readings)
    assert radius.factor == centre.factor == CORRELATION and len(centre.needed) == 4


def test_arc_ratios_pool_the_seeds_per_noise_and_length() -> None:
    def reading(seed: int, error: float) -> ArcReading:
        return ArcReading(0.01, 5.0, seed, 0.0, 1.0, (error, 0.0), (1.0, 0.0, 1.0))

    ratios = arc_ratios([reading(0, 1.0), reading(1, 3.0)])
    assert ratios == {(0.01, 5.0): pytest.approx((1.0 + 9.0) / 4.0)}


# ------------------------------------------------------------------------------ the parser
def test_each_calibration_defaults_to_the_seeds_it_was_measured_on(heft) -> None:
    def parse(*words: str) -> argparse.Namespace:
        return heft.parse_args(["bench", "calibrate", *words])

    args = parse("published-variance")
    assert (args.first_seed, args.seeds, args.ideal_drives, args.generated) == (0, 40, False, False)
    assert parse("published-variance", "--generated").generated
    args = parse("direction-variance", "--seeds", "3")
    assert (args.first_seed, args.seeds) == (0, 3)
    args = parse("arc-correlation")
    assert args.seeds == 40 and not hasattr(args, "first_seed")
    with pytest.raises(SystemExit):
        parse("arc-correlation", "--first-seed", "3")  # simulated arcs: seeds 0..N-1
    with pytest.raises(SystemExit):
        parse()  # which factor is required
    assert [c.name for c in CALIBRATIONS] == [
        "published-variance",
        "step5-com-variance",
        "direction-variance",
        "correlation-time",
        "arc-correlation",
    ]


def test_the_command_line_printed_reproduces_the_calibration(heft) -> None:
    published, *_, arcs = CALIBRATIONS
    assert command(published, 20, 40) == (
        "heft bench calibrate published-variance --first-seed 20 --seeds 40"
    )
    assert command(arcs, None, 40) == "heft bench calibrate arc-correlation --seeds 40"
    words = command(published, 7, 2, True).split()
    assert words[-1] == "--ideal-drives"
    args = heft.parse_args(words[1:])
    assert (args.calibration, args.first_seed, args.seeds, args.ideal_drives) == (
        "published-variance",
        7,
        2,
        True,
    )


@pytest.mark.parametrize(
    "words, message",
    [
        (["correlation-time", "--seeds", "0"], "--seeds: expected an integer in [1, 1000]"),
        (["published-variance", "--first-seed", "-1"], "--first-seed: expected a non-negative"),
        (["arc-correlation", "--seeds", "1001"], "--seeds: expected an integer in [1, 1000]"),
    ],
)
def test_bad_seeds_are_one_error_line_before_any_run(words, message, capsys) -> None:
    assert main(["bench", "calibrate", *words]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and message in err


def test_the_seeds_are_named_as_a_range() -> None:
    assert seed_range(20, 40) == "seeds 20-59" and seed_range(5, 1) == "seed 5"


def test_the_table_gives_the_factor_its_coverage_and_the_one_for_95_percent() -> None:
    lines = format_factors([Factor("J", 0.4, (0.1, 0.5), " s"), Factor("m", 1.0, ())])
    assert lines[1].split() == ["J", "2", "0.4", "s", "50.0", "%", "0.5", "s"]
    assert lines[2].split() == ["m", "0", "1", "-", "-"]


def test_the_command_line_of_a_calibration_on_generated_floors_reproduces_it(heft) -> None:
    published = CALIBRATIONS[0]
    line = command(published, 0, 40, coulomb=(0.005, 0.03), generated=True)
    assert line == (
        "heft bench calibrate published-variance --first-seed 0 --seeds 40 --generated"
        " --coulomb-range 0.005 0.03"
    )
    args = heft.parse_args(line.split()[1:])
    assert args.generated and tuple(args.coulomb_range) == (0.005, 0.03) and args.first_seed == 0
