"""A photo a robot took (the photograph action): served to those who may view the fleet, shown with its
instruction on the dashboard and in the instruction's live update."""

import pytest
from django.urls import reverse

import live
from execution.models import Execution, Instruction, Photo
from fleetcore import images
from robots.models import Robot

PNG = images.png(2, 1, b"\0" + bytes((255, 0, 0, 0, 0, 255)))


@pytest.fixture
def photo(fleet):
    """A photo turtlebot took for a finished instruction."""
    instruction = Instruction.objects.create(text="turtlebot, take a photo", status="succeeded")
    execution = Execution.objects.create(
        instruction=instruction, robot=Robot.objects.get(name="turtlebot"), status="succeeded"
    )
    return Photo.objects.create(
        execution=execution, image=PNG, format="png", width=2, height=1, topic="/camera/image_raw/compressed"
    )


def test_an_anonymous_caller_is_sent_to_the_login_not_the_photo(client, photo):
    response = client.get(reverse("photo", args=[photo.pk]))
    assert response.status_code == 302 and "/login" in response["Location"]


def test_a_viewer_gets_the_png_itself(client_for, viewer, photo):
    response = client_for(viewer).get(reverse("photo", args=[photo.pk]))
    assert (response.status_code, response["Content-Type"]) == (200, "image/png")
    assert response.content == PNG and images.size(response.content) == ("png", 2, 1)
    assert client_for(viewer).get(reverse("photo", args=[photo.pk + 1])).status_code == 404


def test_the_dashboard_shows_the_photo_with_its_instruction(client_for, viewer, photo):
    page = client_for(viewer).get(reverse("dashboard")).content.decode()
    url = reverse("photo", args=[photo.pk])
    assert f'<a href="{url}"><img class="thumb" src="{url}" alt="photo"></a>' in page


def test_the_instructions_live_update_links_its_photos(photo, monkeypatch):
    sent = []
    monkeypatch.setattr(live, "send_on_commit", lambda group, payload: sent.append(payload))
    live.instruction(photo.execution.instruction)
    assert sent[0]["photos"] == [reverse("photo", args=[photo.pk])]
