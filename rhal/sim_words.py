"""The words the simulated robot draws on its top view: the room names beside the landmarks'
QR codes and the readings panel's labels, per language (the sim's ``language`` option).

The picture is one stream for all who watch the robot (the robot's page, the run page), so
its words are the robot's, like its voice (the ``speech`` setting): set on the robot's
settings page. rhal has no Django, hence a table here rather than the pages' catalogs. The
codes themselves keep their text ("home"): it is what programs read with scan_barcode().
"""

WORDS: dict[str, dict[str, str]] = {
    "en": {},  # as written: the codes' own text and rhal's labels
    "pt-br": {
        "home": "casa",
        "kitchen": "cozinha",
        # "lab" as it is: "lab" is said in Portuguese too, and the picture's font (Pillow's
        # default) has no accented letters, so no word here has one.
        "garage": "garagem",
        "hdg": "rumo",
        "rng": "dist",
        "BUMP": "BATEU",
    },
}
LANGUAGES = tuple(WORDS)


def word(language: str, text: str) -> str:
    """``text`` (a code's text, a panel label) as the sim draws it in ``language``."""
    return WORDS.get(language, {}).get(text, text)
