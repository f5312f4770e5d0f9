"""The pages in Brazilian Portuguese, for a browser whose language is pt-BR.

Per page a sample of Portuguese strings is shown and none of a list of English ones is left;
the scripts' own strings (the workbench's save state) come from the JavaScript catalog.
Screenshots: test-artifacts/screenshots/i18n-*.png.
"""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import ADMIN_PASSWORD

SOURCE = "print('olá')\n"
MENU_ENGLISH = ["Programs", "Runs", "Robots", "Languages", "Sign out", "Show the pages in"]


@pytest.fixture
def page(new_page) -> Page:
    """Admin, signed in through the Portuguese sign-in page."""
    page = new_page(locale="pt-BR")
    page.goto("/accounts/login/")
    expect(page.get_by_role("heading", name="Entrar")).to_be_visible()
    page.get_by_label("Nome de usuário").fill("admin")
    page.get_by_label("Senha").fill(ADMIN_PASSWORD)
    page.get_by_role("button", name="Entrar").click()
    expect(page.get_by_role("button", name="Sair")).to_be_visible()
    return page


def shows(page: Page, name: str, portuguese: list[str], english: list[str], screenshot) -> None:
    """The page shows each Portuguese string and no English one (whole words) of the lists,
    whatever their case."""
    expect(page.locator("html")).to_have_attribute("lang", "pt-br")
    text = page.locator("body").inner_text()  # as rendered: the admin's headers in capitals
    missing = [p for p in portuguese if p.casefold() not in text.casefold()]
    left = [e for e in english if re.search(rf"(?<!\w){re.escape(e)}(?!\w)", text, re.I)]
    screenshot(page, f"i18n-{name}")
    assert not missing and not left, f"{name}: missing {missing}, English left {left}"


def test_the_pages_speak_portuguese(page, appliance, screenshot):
    program = appliance.create_program("Olá robô", SOURCE)
    run = appliance.run_program(program["id"])
    appliance.wait_run(run["id"])
    appliance.new_user("i18n-bia")

    page.goto("/programs/")
    shows(
        page, "programs",
        ["Programas", "Execuções", "Robôs", "Linguagens", "Sair", "Novo programa",
         "Enviar um arquivo", "Todos os meus programas", "Dono", "Alterado"],
        [*MENU_ENGLISH, "New program", "Upload a file", "Owner", "Changed", "Download"],
        screenshot,
    )  # fmt: skip
    expect(page.get_by_label("Mostrar as páginas em")).to_have_value("pt-br")

    page.goto(f"/programs/{program['id']}/")
    shows(
        page, "workbench",
        ["Salvar e executar", "Salvar como", "Revisões", "Atalhos", "Compartilhado com",
         "Enviar por e-mail", "Execuções recentes", "PARADA DE EMERGÊNCIA"],
        [*MENU_ENGLISH, "Save and run", "Save as", "Revisions", "Keys", "Shared with",
         "Send by e-mail", "Recent runs", "EMERGENCY STOP", "Hide the robot"],
        screenshot,
    )  # fmt: skip
    # The scripts' strings: the save state comes from the JavaScript catalog.
    page.evaluate("text => window.robotideEditor.setValue(text)", "print('olá de novo')\n")
    expect(page.locator("#save-state")).to_have_text("Mudanças não salvas")
    page.get_by_role("button", name="Salvar", exact=True).click()
    expect(page.locator("#save-state")).to_have_text(re.compile(r"^Salvo \(revisão 2\)$"))

    # Sharing, on the program's page.
    card = page.locator("section.shares")
    card.get_by_label("Compartilhar com").fill("user:i18n-bia")
    card.get_by_role("button", name="Compartilhar", exact=True).click()
    expect(card.locator(".share-list")).to_contain_text("somente leitura")
    shows(
        page, "sharing", ["Compartilhado com", "Deixar de compartilhar", "pode editar"],
        ["Shared with", "Unshare", "may edit", "read-only", "Only you."], screenshot,
    )  # fmt: skip

    page.goto(f"/runs/{run['id']}/")
    shows(
        page, "run",
        [f"Execução nº {run['id']}:", "Acompanhar a saída", "Baixar o registro", "olá"],
        [*MENU_ENGLISH, "Follow output", "Download log", "exit code", "took"],
        screenshot,
    )  # fmt: skip

    page.goto("/runs/")
    shows(
        page, "runs", ["Em execução agora", "Terminadas", "Execução", "Duração", "Registro"],
        [*MENU_ENGLISH, "Running now", "Finished", "Duration", "Log"], screenshot,
    )  # fmt: skip

    page.goto("/robots/sim/")
    shows(
        page, "robot",
        ["Pilotar manualmente", "Sensores", "Em execução aqui", "Executar um programa",
         "Paradas de emergência", "Configurações", "PARADA DE EMERGÊNCIA", "Comandos"],
        [*MENU_ENGLISH, "Drive by hand", "Sensors", "Running here", "Run a program",
         "Emergency stops", "Settings", "EMERGENCY STOP", "Commands", "Last minute"],
        screenshot,
    )  # fmt: skip

    page.goto("/accounts/")
    expect(page).to_have_title("Sua conta · robotide")
    shows(
        page, "account",
        ["Mudar a sua senha", "Tokens da API", "Novo token", "Criar token", "Idioma"],
        [*MENU_ENGLISH, "Change your password", "API tokens", "New token", "Create token"],
        screenshot,
    )  # fmt: skip

    page.goto("/admin/")
    shows(
        page, "admin",
        ["Linguagens dos programas", "Ações recentes", "Encerrar sessão"],
        ["Languages of programs", "Recent actions", "Log out"], screenshot,
    )  # fmt: skip


def test_blocks_speak_portuguese(page, appliance, screenshot):
    """Our blocks and categories from the JavaScript catalog, Blockly's own from its pt-br.js."""
    program = appliance.create_program("Blocos", "", language="blocks")
    page.goto(f"/programs/{program['id']}/")
    toolbox = page.locator(".blocklyToolbox, .blocklyToolboxDiv").first
    expect(toolbox).to_contain_text("Robô")
    expect(toolbox).to_contain_text("Lógica")
    expect(toolbox).to_contain_text("Laços")
    assert page.evaluate("Blockly.Msg.CONTROLS_IF_MSG_IF") == "se"
    assert page.evaluate("Blockly.Blocks.robot_stop.init && true")
    shows(
        page, "blocks", ["O Python que ele executa", "Copiar como programa Python"],
        [*MENU_ENGLISH, "The Python it runs", "Logic", "Loops"], screenshot,
    )  # fmt: skip


def test_the_switcher_by_keyboard_and_the_choice_kept(page, new_page, screenshot):
    """The menu's switcher works from the keyboard, and the account keeps the choice: a new
    browser asking for pt-BR gets English after signing in."""
    page.goto("/programs/")
    choice = page.get_by_label("Mostrar as páginas em")
    choice.focus()
    choice.select_option("en")
    page.keyboard.press("Tab")  # to the button beside it
    expect(page.get_by_role("button", name="Mudar")).to_be_focused()
    page.keyboard.press("Enter")
    expect(page.get_by_role("heading", name="Programs", exact=True)).to_be_visible()
    expect(page.locator("html")).to_have_attribute("lang", "en")
    screenshot(page, "i18n-switched-to-english")

    other = new_page(locale="pt-BR")
    other.goto("/accounts/login/")
    other.get_by_label("Nome de usuário").fill("admin")
    other.get_by_label("Senha").fill(ADMIN_PASSWORD)
    other.get_by_role("button", name="Entrar").click()
    expect(other.get_by_role("button", name="Sign out")).to_be_visible()

    # Back to Portuguese, for the account and the tests after this one.
    other.get_by_label("Show the pages in").select_option("pt-br")
    other.get_by_role("button", name="Change").click()
    expect(other.get_by_role("button", name="Sair")).to_be_visible()


def test_a_student_in_portuguese_gets_portuguese_examples_and_log_lines(
    new_page, appliance, screenshot
):
    """An account made in English (by a teacher, here the CLI) whose student signs in from a
    Portuguese browser: the examples are the Portuguese ones, and a run's page and its
    downloaded log say robotide's own lines in Portuguese (the log file keeps English)."""
    token = appliance.new_user("i18n-lia", password="lia-pass-1234")
    page = new_page(locale="pt-BR")
    page.goto("/accounts/login/")
    page.get_by_label("Nome de usuário").fill("i18n-lia")
    page.get_by_label("Senha").fill("lia-pass-1234")
    page.get_by_role("button", name="Entrar").click()
    expect(page.get_by_role("button", name="Sair")).to_be_visible()

    page.goto("/programs/")
    for name in ["Bússola", "Andar em quadrado", "Parar antes da parede (Blocos)", "Olá do shell"]:
        expect(page.get_by_role("link", name=name, exact=True)).to_be_visible()
    shows(page, "examples", ["Bússola"], ["Compass", "Drive a square", "Blocks"], screenshot)

    programs = appliance.api("GET", "/api/programs", token=token).json()
    hello = next(p for p in programs if p["name"] == "Olá do shell")
    run = appliance.run_program(hello["id"], token=token)
    ended = appliance.wait_run(run["id"])
    page.goto(f"/runs/{run['id']}/")
    state = {"finished": "concluída", "failed": "falhou"}[ended["state"]]
    expect(page.locator("#log")).to_contain_text(f"[robotide] {state}: código de saída")
    expect(page.locator("#log")).to_contain_text("Meu rumo é")  # the example's own words
    shows(page, "run-log", ["código de saída"], ["exit status", "My heading"], screenshot)
    page.set_viewport_size({"width": 390, "height": 844})
    screenshot(page, "i18n-run-log-390")
    page.goto("/programs/")
    screenshot(page, "i18n-examples-390")

    # As the browser asks for it (Playwright's own requests send no Accept-Language).
    log = page.request.get(f"/runs/{run['id']}/log", headers={"Accept-Language": "pt-BR"}).text()
    assert f"[robotide] {state}: código de saída" in log and "Meu rumo é" in log
