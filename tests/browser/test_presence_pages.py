"""Which robots are there, as a lab sees it: online and offline on the robots page, and the
page of a robot whose agent is away saying since when."""

from playwright.sync_api import expect

from tests.browser.test_pages import sign_in


def test_the_robots_page_says_which_agents_are_there(new_page, appliance, screenshot):
    code = "from robots.models import Robot; Robot.objects.get_or_create(name='away', url='sim://')"
    appliance.cli("manage", "shell", "-c", code)  # known, but no agent serves it
    page = new_page()
    sign_in(page)
    page.goto("/robots/")
    sim = page.get_by_role("row").filter(has_text="Simulated robot")
    expect(sim.locator(".badge.online")).to_have_text("online")
    away = page.get_by_role("row").filter(has=page.get_by_role("link", name="away"))
    expect(away.locator(".badge.offline")).to_have_text("offline")
    expect(away).to_contain_text("never seen")
    screenshot(page, "robots-presence")
    page.goto("/robots/away/")
    expect(page.get_by_role("listitem").filter(has_text="agent is offline")).to_contain_text(
        "it has never run"
    )
    screenshot(page, "robot-offline")
