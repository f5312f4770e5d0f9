"""/healthz, as a load balancer or the compose health check asks it: no sign-in needed."""

import pytest

pytestmark = pytest.mark.django_db


def test_healthy_when_the_database_and_the_channel_layer_answer(client):
    response = client.get("/healthz")
    assert response.status_code == 200
    assert response.json() == {"database": "ok", "channels": "ok"}


def test_unhealthy_names_what_does_not_answer(client, monkeypatch):
    def away():
        raise ConnectionError("redis is down")

    monkeypatch.setattr("robotide.views_health.get_channel_layer", away)
    response = client.get("/healthz")
    assert response.status_code == 503
    assert response.json() == {"database": "ok", "channels": "failed: ConnectionError"}
