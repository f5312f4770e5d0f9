"""The robot admin page's inline formsets, as a test posts its form."""


def no_inline_rows(**rows) -> dict:
    """The admin's inline formsets (gateway endpoints, serial bridges): none, or one each."""
    data = {}
    for prefix in ("endpoints", "bridges"):
        given = rows.get(prefix, {})
        data.update({f"{prefix}-TOTAL_FORMS": "1" if given else "0",
                     f"{prefix}-INITIAL_FORMS": "0"})  # fmt: skip
        data.update({f"{prefix}-0-{k}": v for k, v in given.items()})
    return data
