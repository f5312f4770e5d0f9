from pathlib import Path

from django.conf import settings
from django.db.models.signals import post_save
from django.dispatch import receiver

from programs.languages import LANGUAGES, language_for_filename

EXAMPLES_DIR = Path(__file__).resolve().parent / "examples"
EXAMPLES = {
    "compass.py": "Compass",
    "square.py": "Drive a square",
    "wall.py": "Stop before the wall",
    "hello.sh": "Hello from the shell",
    "any_robot.py": "Any robot: forward, turn, stop",
    "im_home.py": "I'm home (barcode landmarks)",
    "voice_move.py": "Say move and the robot moves",
    # Blocks (Blockly's JSON) for beginners, run as the Python made of them
    "wall.json": "Stop before the wall (Blocks)",
    "square.json": "Drive a square (Blocks)",
    # The same program in every language: the Robot API is the same in each.
    **{
        f"wall_turn{lang.extension}": f"Wall and turn ({lang.label})" for lang in LANGUAGES.values()
    },
}


def create_examples(user) -> None:
    """Every new account starts with the examples, so a newcomer can press Run at once."""
    from programs.models import Program

    for filename, name in EXAMPLES.items():
        if Program.objects.filter(owner=user, name=name).exists():
            continue
        language = language_for_filename(filename)
        program = Program.objects.create(owner=user, name=name, language=language.name)
        program.save_source((EXAMPLES_DIR / filename).read_text(), user)


@receiver(post_save, sender=settings.AUTH_USER_MODEL)
def give_new_user_examples(sender, instance, created, raw=False, **kwargs):
    if created and not raw:
        create_examples(instance)
