"""The dashboard's web API (dashboard/app.py) through FastAPI's TestClient, the WebSocket
included: the snapshot and summary of a real run of the paper's scenario, frames, the token
on every endpoint, bad requests, and ``heft dashboard``'s bad input."""

from __future__ import annotations

import contextlib
import io
import json

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from agent.platform.heft import main
from agent.platform.protocol import Estimates, Phase
from dashboard.app import AppSettings, create_app
from dashboard.hub import Hub
from tests.helpers.paths import PAPER


@pytest.fixture(scope="module")
def paper_run():
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario

    scenario = load_scenario(PAPER)
    return scenario, run_inprocess(scenario)


def fed_hub(paper_run, upto: int | None = None) -> Hub:
    """A hub that has heard the run (up to its ``upto``-th recorded instant), after the
    plant's load geometry."""
    scenario, outcome = paper_run
    hub = Hub("paper")
    hub.ingest_batch([("", scenario.load_geometry(), 0.0, 0)])
    samples = [*outcome.history, outcome.final][:upto]
    for sample in samples:
        batch = [("", sample.truth, sample.time_s, 0)]
        batch += [("", est, sample.time_s, 0) for est in sample.estimates.values()]
        hub.ingest_batch(batch)
    return hub


def test_snapshot_and_summary_of_a_run(paper_run) -> None:
    _, outcome = paper_run
    with TestClient(create_app(fed_hub(paper_run))) as client:
        snapshot = client.get("/api/snapshot").json()
        assert snapshot["team"] == "paper" and snapshot["n"] == 4 and snapshot["done"]
        assert snapshot["truth"]["mass"] == 5.0
        for i, est in outcome.final.estimates.items():
            robot = snapshot["robots"][str(i)]
            assert robot["phase"] == "done"
            assert abs(robot["mass"] - 5.0) < 1e-3
            assert set(robot["relative_positions"]) == {str(j) for j in est.relative_positions}
            assert len(robot["contact_to_com"]) == 2
        assert {tuple(link["edge"]) for link in snapshot["links"]} == {(1, 2), (2, 3), (3, 4)}
        summary = client.get("/api/summary").json()
        assert summary["final"] and summary["tick"] == outcome.final.truth.tick
        assert summary["robots"]["1"]["mass"] == outcome.final.estimates[1].mass
        assert summary["worst"]["mass_rel"] < 1e-4
        series = client.get("/api/series").json()
        assert abs(series["mass/2"][-1][1] - 5.0) < 1e-3


def test_no_summary_before_the_team_is_done(paper_run) -> None:
    with TestClient(create_app(fed_hub(paper_run, upto=50))) as client:
        response = client.get("/api/summary")
        assert response.status_code == 404
        assert response.json() == {"detail": "no final table yet: the team is not done"}


def test_the_websocket_sends_a_hello_then_frames_of_new_points(paper_run) -> None:
    scenario, outcome = paper_run
    hub = fed_hub(paper_run, upto=40)
    with TestClient(create_app(hub, AppSettings(frame_hz=50))) as client:
        with client.websocket_connect("/ws") as ws:
            hello = ws.receive_json()
            assert hello["type"] == "hello" and hello["epoch"] == 1
            assert hello["source"]["mode"] == "live"
            last = hello["series"]["omega/1"][-1][0]
            sample = outcome.history[60]
            hub.ingest_batch([("", est, 0.0, 0) for est in sample.estimates.values()])
            frame = ws.receive_json()
            while "omega/1" not in frame["points"]:
                frame = ws.receive_json()
            assert frame["type"] == "frame"
            assert frame["points"]["omega/1"][-1][0] > last
            assert frame["scene"]["robots"]["1"]["tick"] == sample.estimates[1].tick


def test_the_page_and_the_charting_libraries_are_served(paper_run) -> None:
    with TestClient(create_app(fed_hub(paper_run, upto=1))) as client:
        page = client.get("/")
        assert page.status_code == 200
        for path in ("vendor/uplot.js", "vendor/uplot.css"):
            assert path in page.text
        assert "plotly" not in page.text
        assert client.get("/static/dashboard.js").status_code == 200
        uplot = client.get("/vendor/uplot.js")  # installed by make from the npm registry
        assert uplot.status_code == 200, uplot.text
        assert uplot.headers["content-type"].startswith("text/javascript")
        assert b"uPlot" in uplot.content and len(uplot.content) > 20_000
        assert client.get("/vendor/uplot.css").headers["content-type"].startswith("text/css")
        unknown = client.get("/vendor/jquery.js")
        assert unknown.status_code == 404 and "no such file" in unknown.json()["detail"]
        missing = client.get("/nothing")
        assert missing.status_code == 404 and missing.json()["detail"]


def test_a_token_guards_every_endpoint(paper_run) -> None:
    app = create_app(fed_hub(paper_run, upto=5), AppSettings(token="s3cret"))
    with TestClient(app) as client:
        for path in ("/", "/api/snapshot", "/api/summary", "/vendor/uplot.js", "/static/x"):
            response = client.get(path)
            assert response.status_code == 401, path
            assert "token is required" in response.json()["detail"]
        assert client.get("/api/snapshot?token=wrong").json() == {"detail": "wrong token"}
        assert client.post("/api/replay", json={"action": "pause"}).status_code == 401
        with pytest.raises(WebSocketDisconnect) as refused:
            with client.websocket_connect("/ws") as ws:
                ws.receive_json()
        assert refused.value.code == 1008
        headers = {"Authorization": "Bearer s3cret"}
        assert client.get("/api/snapshot", headers=headers).status_code == 200
        assert client.get("/api/snapshot", headers={"X-Heft-Token": "s3cret"}).status_code == 200
        with client.websocket_connect("/ws?token=s3cret") as ws:
            assert ws.receive_json()["type"] == "hello"
    with TestClient(app) as browser:  # the page opened with ?token=: a cookie for the rest
        assert browser.get("/?token=s3cret").status_code == 200
        assert browser.get("/api/snapshot").status_code == 200
        with browser.websocket_connect("/ws") as ws:
            assert ws.receive_json()["type"] == "hello"


def test_bad_replay_requests_get_4xx_with_a_reason(paper_run) -> None:
    with TestClient(create_app(fed_hub(paper_run, upto=5))) as client:
        response = client.post("/api/replay", json={"action": "restart"})
        assert response.status_code == 409 and response.json()["detail"] == "no recording to replay"
        response = client.post("/api/replay", json={"action": "pause"})
        assert response.status_code == 409 and "not replaying" in response.json()["detail"]
        response = client.post("/api/replay", json={"action": "fly"})
        assert response.status_code == 422 and response.json()["detail"]
        response = client.post("/api/replay", json={"action": "play", "speed": -1})
        assert response.status_code == 422
        response = client.post(
            "/api/replay", content=b"{", headers={"content-type": "application/json"}
        )
        assert response.status_code == 422


# ------------------------------------------------------------------------------ heft dashboard
def heft(*argv: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(list(argv))
    return code, err.getvalue()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (("--host", "0.0.0.0", "--team", "t"), "--host 0.0.0.0: listening beyond this machine"),
        (("--port", "70000", "--team", "t"), "--port: expected 0 to 65535"),
        ((), "--team: needed to watch a live team"),
        (("--team", "a/b"), "--team: team name"),
        (("--replay", "/nonexistent.mcap"), "--replay: /nonexistent.mcap: no such file"),
        (("--replay", "/etc/hostname"), "not an MCAP file"),
        (("--team", "t", "--speed", "2"), "--speed and --paused need --replay FILE"),
        (("--replay", "x.mcap", "--speed", "0"), "--speed: expected"),
        (("--team", "t", "--connect", "nowhere"), "--connect: expected an explicit endpoint"),
        (("--team", "t", "--scenario", "paper.toml"), "--scenario: no longer needed: the plant"),
        (("--replay", "x.mcap", "--foxglove"), "--foxglove serves a live team: open the recording"),
    ],
)
def test_bad_input_is_one_error_line_and_status_2(argv, message, monkeypatch) -> None:
    monkeypatch.delenv("HEFT_DASHBOARD_TOKEN", raising=False)
    code, err = heft("dashboard", "--port", "0", *argv)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("heft: error: "), err
    assert message in lines[0]


def test_heft_record_refuses_a_scenario_and_says_where_the_outline_comes_from(tmp_path) -> None:
    out = tmp_path / "run.mcap"
    code, err = heft("record", "--team", "t", "-o", str(out), "--scenario", "paper.toml")
    assert code == 2 and not out.exists()
    assert err == (
        "heft: error: --scenario: no longer needed: the plant (heft sim, heft run) publishes"
        " the load's outline and the graph, and a recording keeps them\n"
    )


def test_the_estimates_json_is_finite(paper_run) -> None:
    """Every value the page gets is plain JSON (no NaN or infinity)."""
    hub = fed_hub(paper_run)
    hub.ingest_batch([("", Estimates(1, 99999, Phase.DONE, phase_since=1), 0.0, 0)])
    json.dumps(hub.hello(), allow_nan=False)
    json.dumps(hub.frame(), allow_nan=False)
