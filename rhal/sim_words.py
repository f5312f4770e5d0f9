"""The words the simulated robot draws on its top view: the built-in worlds' room and zone
names (beside the landmarks' QR codes, on the zones) and the readings panel's labels, per
language (the sim's ``language`` option). A world of a teacher's keeps its own words: only the
built-in worlds' are translated (rhal.sim_render).

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
        # "lab" as it is: "lab" is said in Portuguese too.
        "garage": "garagem",
        "bedroom": "quarto",
        "hall": "corredor",
        "start": "início",
        "goal": "chegada",
        "hdg": "rumo",
        "rng": "dist",
        "BUMP": "BATEU",
    },
}
LANGUAGES = tuple(WORDS)


def word(language: str, text: str) -> str:
    """``text`` (a code's text, a panel label) as the sim draws it in ``language``."""
    return WORDS.get(language, {}).get(text, text)
