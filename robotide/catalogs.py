"""The translation catalogs: every `locale` folder of the project, filled by makemessages.

One makemessages run from the project's root fills them all: Django sends a file's strings to
the nearest `locale` folder above it (programs/locale, robots/locale), and the rest (templates/,
robotide/, the scripts) to the root's locale/. `make messages` updates the root's catalogs;
tests/test_i18n.py runs it over a copy of the tree and checks every catalog is complete.
"""

import os
from pathlib import Path

from django.conf import settings
from django.core.management import call_command
from django.test.utils import override_settings

# What makemessages never reads: environments, data, tests, other projects' code.
IGNORE = [
    ".venv",
    ".git",
    "var",
    "node_modules",
    "test-artifacts",
    "tests",
    "docs",
    "benchmarks",
    "robotide/static/vendor",
    "*.egg-info",
]
DOMAINS = {"django": ["html", "txt", "py"], "djangojs": ["js"]}


def locale_dirs(root: Path) -> list[Path]:
    """Every `locale` folder under ``root``, outside what makemessages ignores."""
    found = []
    for dirpath, dirnames, _files in os.walk(root):
        here = Path(dirpath)
        dirnames[:] = [d for d in dirnames if not _ignored(here / d, root)]
        if "locale" in dirnames:
            found.append(here / "locale")
            dirnames.remove("locale")
    return sorted(found)


def _ignored(path: Path, root: Path) -> bool:
    relative = path.relative_to(root)
    return any(relative.match(pattern) for pattern in IGNORE)


def make_messages(root: Path, locale: str, *, skip: list[str] = ()) -> None:
    """Update ``root``'s catalogs for ``locale`` (pt_BR) from its sources; folders in ``skip``
    (another app's, say) are not read, so their catalogs stay as they are."""
    cwd = os.getcwd()
    os.chdir(root)
    try:
        with override_settings(LOCALE_PATHS=[root / "locale"]):
            for domain, extensions in DOMAINS.items():
                call_command(
                    "makemessages",
                    locale=[locale],
                    domain=domain,
                    extensions=extensions,
                    ignore_patterns=[*IGNORE, *skip],
                    add_location="file",
                    verbosity=0,
                )
    finally:
        os.chdir(cwd)


def translated_locales() -> list[str]:
    """The locales (pt_BR) of settings.LANGUAGES that need catalogs: all but English."""
    from django.utils.translation import to_locale

    return [to_locale(code) for code, _name in settings.LANGUAGES if code != "en"]


def update_root_catalogs(locale: str) -> None:
    """`make messages`: the root's catalogs, made and compiled (the .mo files are committed, so
    serving needs no gettext), leaving the apps' own catalogs to their owners."""
    root = Path(settings.BASE_DIR)
    # "programs/?*", not "programs" or "programs/*" (which Django cuts to "programs"): those
    # would skip templates/programs/ too, as a pattern without "/" matches a name anywhere.
    apps = [f"{d.parent.relative_to(root)}/?*" for d in locale_dirs(root) if d.parent != root]
    make_messages(root, locale, skip=apps)
    cwd = os.getcwd()
    os.chdir(root)
    try:
        call_command("compilemessages", locale=[locale], ignore_patterns=[*IGNORE, *apps])
    finally:
        os.chdir(cwd)


if __name__ == "__main__":
    import django

    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "robotide.settings")
    django.setup()
    for each in translated_locales():
        update_root_catalogs(each)
