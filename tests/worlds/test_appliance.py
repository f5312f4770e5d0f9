"""End to end on a running appliance (issue 30): a world posted to /api/worlds, a personal sim
made in it (POST /api/sims {"world": id}), the sim's agent runs it in that document (what the
robot page draws from, /robots/<name>/world.json); a save reaches the sim; once the world is
deleted the sim does not open and its page says why; a student who may not see the world cannot
put a sim in it."""

from tests.appliance import wait_for
from tests.worlds.documents import corridor

PASSWORD = "user-pass-1234"


def world_of(appliance, session, robot: str) -> dict | None:
    answer = session.get(f"/robots/{robot}/world.json")
    return answer.json().get("world") if answer.status_code == 200 else None


def test_a_sim_in_a_stored_world(appliance):
    token = appliance.new_user("wilma", PASSWORD)
    created = appliance.api("POST", "/api/worlds", corridor(), token=token)
    assert created.status_code == 201, created.text
    world = created.json()
    sim = appliance.api("POST", "/api/sims", {"world": world["id"]}, token=token)
    assert sim.status_code == 201, sim.text
    robot = sim.json()["name"]
    session = appliance.session("wilma", PASSWORD)
    wait_for(lambda: world_of(appliance, session, robot) == world["document"], what="the world")

    moved = corridor(start=[{"x": -1.5, "y": 1.0, "theta": 0.0}])
    saved = appliance.api("PUT", f"/api/worlds/{world['id']}", moved, token=token).json()
    assert saved["revision"] == 2
    wait_for(lambda: world_of(appliance, session, robot) == saved["document"], what="the save")

    # Gone: the sim no longer opens, and its page says why.
    assert appliance.api("DELETE", f"/api/worlds/{world['id']}", token=token).status_code == 204

    def why_not_open():
        sensors = appliance.api("GET", f"/api/robots/{robot}/sensors", token=token)
        return sensors.status_code == 503 and "no world" in sensors.json()["detail"]

    wait_for(why_not_open, what="the sim saying its world is gone")
    page = session.get(f"/robots/{robot}/")
    assert page.status_code == 200 and "no world" in page.text, page.text[-2000:]

    other = appliance.new_user("wendell", PASSWORD)
    refused = appliance.api("POST", "/api/sims", {"world": world["id"]}, token=other)
    assert refused.status_code in (404, 409, 422), refused.text
    assert "world" in refused.json()["detail"]
