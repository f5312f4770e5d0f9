"""The example programs every account starts with, in the account's language.

Each example is one file per language: programs/examples/ (English) and, beside it, a folder per
translated language (programs/examples/pt_BR/) with the same file names, whose comments,
printed and spoken texts are that language's; a file missing there falls back to English. The
names are msgids, translated by the catalog (programs/locale).

An account gets them in the language it is created in (its stored choice, else the language of
the page or command that creates it). While an example is untouched (never saved, run, shared,
drafted or given a robot's button), it follows the account's language: choosing another in the
menu or the account page, or signing in with a browser that shows the pages in another, swaps it
for the same example in that language. A student whose account a teacher made in English thus
finds Portuguese examples at their first sign-in in Portuguese, and nothing a user changed or
ran is ever replaced.
"""

from pathlib import Path

from django.conf import settings
from django.contrib.auth.signals import user_logged_in
from django.db import transaction
from django.db.models.signals import post_save
from django.dispatch import receiver
from django.utils import translation
from django.utils.translation import gettext, gettext_noop

from programs.languages import LANGUAGES, language_for_filename

EXAMPLES_DIR = Path(__file__).resolve().parent / "examples"
EXAMPLES = {
    "compass.py": gettext_noop("Compass"),
    "square.py": gettext_noop("Drive a square"),
    "wall.py": gettext_noop("Stop before the wall"),
    "hello.sh": gettext_noop("Hello from the shell"),
    "any_robot.py": gettext_noop("Any robot: forward, turn, stop"),
    "im_home.py": gettext_noop("I'm home (barcode landmarks)"),
    "voice_move.py": gettext_noop("Say move and the robot moves"),
    # Blocks (Blockly's JSON) for beginners, run as the Python made of them
    "wall.json": gettext_noop("Stop before the wall (Blocks)"),
    "square.json": gettext_noop("Drive a square (Blocks)"),
    # The same program in every language: the Robot API is the same in each.
    **{
        f"wall_turn{lang.extension}": f"Wall and turn ({lang.label.split(' (')[0]})"
        for lang in LANGUAGES.values()
    },
}
WALL_AND_TURN = gettext_noop("Wall and turn (%(language)s)")  # the names above, translated


def short_label(filename: str) -> str:
    """The language's label without what it adds in brackets ("JavaScript (Node.js)"), which
    inside the example's own brackets read as doubled ones."""
    return str(language_for_filename(filename).label).split(" (")[0]


def example_name(filename: str, language: str) -> str:
    """The example's name in ``language`` (a code of settings.LANGUAGES, "pt-br"); in English,
    the name EXAMPLES gives."""
    with translation.override(language):
        if filename.startswith("wall_turn"):
            return gettext(WALL_AND_TURN) % {"language": short_label(filename)}
        return gettext(EXAMPLES[filename])


def example_source(filename: str, language: str) -> str:
    translated = EXAMPLES_DIR / translation.to_locale(language) / filename
    return (translated if translated.exists() else EXAMPLES_DIR / filename).read_text()


def account_language(user) -> str:
    """The language an account's examples are made in: its stored choice, else the one active
    (the page's, or settings.LANGUAGE_CODE for a command), else English."""
    from robotide.language import stored_language, supported

    code = stored_language(user) or translation.get_language()
    return code if supported(code) else settings.LANGUAGE_CODE


def create_examples(user, language: str | None = None) -> None:
    """Every new account starts with the examples, so a newcomer can press Run at once."""
    from programs.models import Program

    language = language or account_language(user)
    for filename in EXAMPLES:
        name = example_name(filename, language)
        if Program.objects.filter(owner=user, name=name).exists():
            continue
        kind = language_for_filename(filename)
        program = Program.objects.create(owner=user, name=name, language=kind.name)
        program.save_source(example_source(filename, language), user)


def follow_language(user, language: str) -> int:
    """The account's untouched examples made again in ``language``; how many were. One query
    when there is nothing to do (every sign-in asks)."""
    from programs.models import Program

    names = {  # every example's name in every language: (file, language)
        example_name(filename, code): (filename, code)
        for filename in EXAMPLES
        for code, _label in settings.LANGUAGES
    }
    have = {p.name: p for p in Program.objects.filter(owner=user, name__in=list(names))}
    swapped = 0
    for name, program in have.items():
        filename, code = names[name]
        wanted = example_name(filename, language)
        if wanted in have or not _untouched(program, example_source(filename, code)):
            continue
        with transaction.atomic():
            program.delete()
            kind = language_for_filename(filename)
            made = Program.objects.create(owner=user, name=wanted, language=kind.name)
            made.save_source(example_source(filename, language), user)
        swapped += 1
    return swapped


def _untouched(program, source: str) -> bool:
    """As the account got it: one revision, the example's text, no run, share, draft, origin
    or button (a teacher's robot button may name it)."""
    from robots.models import RobotButton

    return (
        program.source == source
        and not program.origin
        and list(program.revisions.values_list("source", flat=True)) == [source]
        and not program.runs.exists()
        and not program.shares.exists()
        and not program.drafts.exists()
        and not RobotButton.objects.filter(program=program).exists()
    )


@receiver(post_save, sender=settings.AUTH_USER_MODEL)
def give_new_user_examples(sender, instance, created, raw=False, **kwargs):
    if created and not raw:
        create_examples(instance)


@receiver(post_save, sender="robotide.LanguagePreference")
def examples_follow_the_choice(sender, instance, raw=False, **kwargs):
    """A language chosen in the menu or on the account page."""
    if not raw:
        follow_language(instance.user, instance.language)


@receiver(user_logged_in)
def examples_follow_the_sign_in(sender, request, user, **kwargs):
    """At sign-in: the language the pages will be in (the account's, else the browser's)."""
    follow_language(user, account_language(user))
