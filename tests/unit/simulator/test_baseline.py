"""The centralized reference (simulator/baseline.py, ``heft baseline``): fitted to a run of the
plant recorded as a team's recording, it finds the load's mass, moment of inertia and contact
offsets, exactly without noise and within its own uncertainty with it, and no friction on the
plant's frictionless floor (its friction on a floor that has some: test_baseline_friction)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from agent.platform.heft import main
from agent.platform.protocol import Keys
from dashboard.recorder import Recorder
from simulator.baseline import fit, read_recording
from simulator.plant import Plant
from simulator.scenario import Sensors, load_scenario
from tests.helpers.paths import PAPER

SECONDS = 4.0


def excited_run(velocity_noise: float = 0.0, force_noise: float = 0.0, path=None):
    """The paper's load pushed by forces that turn and move it (sines of random amplitude,
    frequency and phase), ``SECONDS`` long: the measurements as arrays, and the truth at
    the end; written as a team's recording to ``path`` when given."""
    scenario = load_scenario(PAPER)
    sensors = Sensors(rate_hz=100.0, velocity_noise_std=velocity_noise, force_noise_std=force_noise)
    scenario = replace(scenario, sensors=sensors)
    plant = Plant(scenario)
    rng = np.random.default_rng(3)
    amplitude = rng.uniform(1.0, 3.0, (scenario.n, 2))
    frequency = rng.uniform(0.5, 2.5, (scenario.n, 2))
    phase = rng.uniform(0.0, 2 * math.pi, (scenario.n, 2))
    keys = Keys("baseline")
    recorder = Recorder(path, keys.team) if path is not None else None
    velocities, forces = [], []
    ticks = round(SECONDS * scenario.sensors.rate_hz)
    for k in range(ticks + 1):
        measured = plant.measure()
        velocities.append([m.velocity for m in measured])
        forces.append([m.force for m in measured])
        if recorder is not None:
            stamp = 1_700_000_000_000_000_000 + k * 10_000_000
            recorder.write(keys.truth(), plant.truth(), stamp)
            for m in measured:
                recorder.write(keys.velocity(m.robot), m, stamp)
        t = k * scenario.period_s
        for i in range(scenario.n):
            plant.command(i + 1, tuple(amplitude[i] * np.sin(frequency[i] * t + phase[i])))
        if k < ticks:
            plant.advance()
    if recorder is not None:
        recorder.close()
    return np.array(velocities), np.array(forces), scenario.period_s, plant.truth()


def test_without_noise_the_fit_is_the_load() -> None:
    velocities, forces, period, truth = excited_run()
    result = fit(velocities, forces, period, 0.0, 0.0)
    assert result.converged and result.ticks == velocities.shape[0]
    assert abs(result.mass - truth.mass) / truth.mass < 1e-4
    # ω is the angle's central difference: J and the offsets carry its O(T²) error.
    assert abs(result.moment - truth.moment) / truth.moment < 1e-3
    for fitted, true in zip(result.contact_to_com, truth.contact_to_com, strict=True):
        assert math.dist(fitted, true) < 1e-3  # m
    assert result.relative_position(1, 2) == pytest.approx(
        np.subtract(truth.contacts[0], truth.contacts[1]), abs=1e-3
    )
    # no friction, to the same O(T²): a caster floor's would be about 1 N m and 0.4 N/m
    assert abs(result.friction_torque) < 2e-3 and abs(result.spin_drag) < 1e-3
    # the sines drive the load across ω = 0: there it slides, against no friction either
    assert 0.5 * result.ticks < result.turning_intervals < result.ticks - 1
    assert result.sliding_intervals > 20 and abs(result.sliding_friction) < 1e-3


def test_with_noise_the_truth_is_within_the_fits_own_uncertainty() -> None:
    velocities, forces, period, truth = excited_run(velocity_noise=0.003, force_noise=0.15)
    result = fit(velocities, forces, period, 0.003, 0.15)
    assert result.converged
    assert 0 < result.mass_std < 0.05 * truth.mass
    assert 0 < result.moment_std < 0.1 * truth.moment
    assert abs(result.mass - truth.mass) < 4 * result.mass_std
    assert abs(result.moment - truth.moment) < 4 * result.moment_std
    assert abs(result.friction_torque) < 4 * result.friction_torque_std
    assert abs(result.spin_drag) < 4 * result.spin_drag_std
    assert abs(result.sliding_friction) < 4 * result.sliding_friction_std
    for fitted, std, true in zip(
        result.contact_to_com, result.contact_to_com_std, truth.contact_to_com, strict=True
    ):
        assert 0 < std < 0.05
        assert math.dist(fitted, true) < 4 * math.sqrt(2) * std


def test_too_little_data_is_refused() -> None:
    with pytest.raises(ValueError, match="too few"):
        fit(np.zeros((5, 4, 2)), np.zeros((5, 4, 2)), 0.01, 0.0, 0.0)
    with pytest.raises(ValueError, match="non-finite"):
        fit(np.full((20, 4, 2), math.nan), np.zeros((20, 4, 2)), 0.01, 0.0, 0.0)


def test_heft_baseline_reads_a_recording_and_prints_the_fit_against_the_truth(
    tmp_path, capsys
) -> None:
    path = tmp_path / "run.mcap"
    _, _, period, truth = excited_run(path=path)
    run = read_recording(path)
    assert run.velocities.shape == (round(SECONDS * 100) + 1, 4, 2)
    assert run.period_s == pytest.approx(period) and run.truth.tick == truth.tick
    out = tmp_path / "fit.json"
    noise = ["--velocity-noise", "0", "--force-noise", "0"]
    assert main(["baseline", str(path), *noise, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "m [kg]" in printed and "J [kg m2]" in printed and "5.00000" in printed
    assert "τ_c [N m]" in printed and "κ [N/m]" in printed
    data = json.loads(out.read_text())
    assert abs(data["mass"] - truth.mass) / truth.mass < 1e-4
    assert data["truth"]["contact_to_com"] == [list(c) for c in truth.contact_to_com]
    assert abs(data["friction_torque"]) < 2e-3 and data["friction_torque_std"] > 0
    assert data["truth"]["friction_torque"] == data["truth"]["spin_drag"] == 0.0
    assert data["truth"]["sliding_friction"] == 0.0 and "F_s [N]" in printed
    # the rigid-body model alone: every interval, no friction
    assert main(["baseline", str(path), *noise, "--no-friction", "--out", str(out)]) == 0
    assert "without friction" in capsys.readouterr().out
    rigid = json.loads(out.read_text())
    assert rigid["friction_torque"] is None and rigid["sliding_friction"] is None
    assert rigid["turning_intervals"] == rigid["ticks"] - 1 and rigid["sliding_intervals"] == 0
    assert abs(rigid["mass"] - truth.mass) / truth.mass < 1e-4


def test_heft_baseline_refuses_bad_input_in_one_line(tmp_path, capsys) -> None:
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello")
    empty = tmp_path / "empty.mcap"
    Recorder(empty, "baseline").close()
    noise = ["--velocity-noise", "0.01", "--force-noise", "0.5"]
    for argv, words in (
        (["baseline", str(not_mcap), *noise], "not an MCAP file"),
        (["baseline", str(empty), *noise], "no robot measurements"),
        (["baseline", str(tmp_path / "none.mcap"), *noise], "cannot read"),
        (["baseline", str(empty), *noise, "--force-noise", "-1"], "--force-noise"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
