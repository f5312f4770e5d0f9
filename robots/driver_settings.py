"""A robot's driver options as a typed form, for the robot page and the admin.

The fields come from the driver's own signature (rhal.options), so a new driver option shows
up here without a change. A value is stored in ``Robot.settings`` only when it differs from
what the robot's URL or the driver's default already say, and the whole set is checked by
building the driver (nothing is opened) before it is saved.
"""

from __future__ import annotations

from typing import Any
from urllib.parse import urlsplit

from django import forms
from django.conf import settings as django_settings
from django.utils.translation import gettext as _
from django.utils.translation import pgettext

import rhal
from rhal.camera import CameraSettings
from rhal.options import Option, driver_options, url_options
from robots.driver_words import option_shown
from robots.fair_shares import robot_setting
from robots.host_services import check_speech_settings
from robots.models import RUN_SETTINGS, Robot
from robots.reset import check_setting as check_start_each_run
from runbox.isolation import IsolationUnavailable, Policy
from runbox.launcher import Limits
from worlds.resolve import options_to_check


def known_driver(url: str) -> str:
    """``url`` if a driver is registered for its scheme, else ValueError naming the known."""
    scheme = urlsplit(url).scheme.lower()
    if scheme not in rhal.DRIVERS:
        known = ", ".join(f"{name}://" for name in sorted(rhal.DRIVERS))
        raise ValueError(
            _("no robot driver for %(url)s; known: %(known)s") % {"url": repr(url), "known": known}
        )
    return url


def check_settings(url: str, settings: dict) -> None:
    """ValueError if an agent could not use these settings: refused now, not found out later."""
    robot = Robot(url=url, settings=settings)
    try:
        Limits.from_settings(settings.get("limits", {}))
        robot_setting(settings)  # runs_at_once
        CameraSettings.parse(settings.get("camera"))
        check_speech_settings(settings.get("speech"))
        check_start_each_run(settings)
        Policy.from_settings(robot.run_isolation(django_settings.RUN_ISOLATION))
        rhal.connect(url, **options_to_check(robot))  # builds the driver, opens nothing
    except (TypeError, ValueError, AttributeError, rhal.RhalError, IsolationUnavailable) as exc:
        raise ValueError(_("settings: %(why)s") % {"why": exc}) from None


def options_for(robot: Robot) -> list[Option]:
    """The driver's options, or none when the URL names no driver that loads here."""
    try:
        options = driver_options(robot.url)
    except rhal.RhalError:
        return []
    return [option_shown(option) for option in options]  # their help in the reader's language


def current_values(robot: Robot) -> list[dict[str, Any]]:
    """Each option with its value in force and where that comes from, for the robot page."""
    query = url_options(robot.url)
    rows = []
    for option in options_for(robot):
        if option.name in robot.settings:
            value, source = robot.settings[option.name], _("set here")
        elif option.name in query:
            value, source = query[option.name], _("from the URL")
        else:
            value, source = option.default, pgettext("source of a value", "default")
        rows.append({"option": option, "value": value, "source": source})
    return rows


def option_field(option: Option, initial: Any) -> forms.Field:
    default = pgettext("no value", "none") if option.default is None else option.default
    help_text = _("%(help)s (default: %(default)s)") % {"help": option.help, "default": default}
    common = {"required": False, "initial": initial, "help_text": help_text.lstrip()}
    if option.kind is bool:
        # An option whose default is "not set" (the driver decides) has three states: a
        # checkbox would store False for "not set".
        return (forms.NullBooleanField if option.default is None else forms.BooleanField)(**common)
    if option.kind is int:
        return forms.IntegerField(**common)
    if option.kind is float:
        return forms.FloatField(**common)
    if option.choices:
        choices = [(choice, choice) for choice in option.choices]
        return forms.ChoiceField(choices=choices, **common)
    return forms.CharField(max_length=500, **common)


def add_option_fields(form: forms.BaseForm, robot: Robot) -> None:
    """Add a field per driver option to ``form``, named ``option_<name>``."""
    for row in current_values(robot):
        option = row["option"]
        form.fields[f"option_{option.name}"] = option_field(option, row["value"])


def settings_from(form: forms.BaseForm, robot: Robot, url: str | None = None) -> dict:
    """The robot's new ``settings`` from a valid form; errors are added to the form.

    Run settings (limits, isolation) are kept as they are; driver options are replaced.
    """
    url = url or robot.url
    query = url_options(url)
    chosen = {}
    for option in options_for(Robot(url=url)):
        key = f"option_{option.name}"
        if key not in form.cleaned_data:
            continue
        value = _typed(option, form.cleaned_data[key])
        baseline = query.get(option.name, option.default)
        if value is not None and value != baseline:
            chosen[option.name] = value
    try:
        # Builds the driver, opens nothing; a stored world named by its document.
        rhal.connect(url, **options_to_check(Robot(url=url, settings=chosen)))
    except (TypeError, ValueError, rhal.RhalError) as exc:
        _add_error(form, exc, chosen)
        return robot.settings
    kept = {k: v for k, v in robot.settings.items() if k in RUN_SETTINGS}
    return {**kept, **chosen}


def _typed(option: Option, value: Any) -> Any:
    if option.kind is str and isinstance(value, str):
        return option.parse(value)
    if option.kind is float and value is not None and float(value).is_integer():
        # 40.0 and the default 40 are the same setting: store what the signature says.
        return int(value) if isinstance(option.default, int) else float(value)
    return value


def _add_error(form: forms.BaseForm, exc: Exception, chosen: dict) -> None:
    message = str(exc)
    for name in chosen:
        if message.startswith(name) and f"option_{name}" in form.fields:
            form.add_error(f"option_{name}", message)
            return
    form.add_error(None, message)
