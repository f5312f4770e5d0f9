"""Choosing a Pioneer's units: the model it names, the settings' model, each override."""

import math

import pytest

import rhal
from rhal.pioneer import PioneerRobot
from rhal.pioneer_units import fit

UNSET = {"model": None}


def test_the_model_the_robot_names_gives_its_units():
    units = fit("P3AT", UNSET)  # ARIA lower-cases the subclass
    assert units.model.subclass == "p3at" and units.model.source.endswith("params/p3at.p")
    assert units.mm_per_unit == 0.465
    assert units.rad_per_unit == math.tau / 4096  # the file's 0.00153, taken exactly
    assert units.track == pytest.approx(2 / 0.0034 / 1000)
    assert len(units.sonars) == 16 and units.front_sonars == (3, 4)
    assert "SYNC2 subclass 'P3AT'" in units.chosen_by


def test_a_pioneer_1_turns_in_1024_units_and_looks_ahead_with_its_middle_disc():
    units = fit("pion1m", UNSET)
    assert units.rad_per_unit == math.tau / 1024
    assert units.mm_s_per_unit == 2.5332 and units.mm_per_range_unit == 0.1734
    assert units.front_sonars == (2, 3, 4)  # -15, 0 and +15 degrees


def test_the_settings_model_wins_and_each_factor_can_be_overridden():
    options = {**UNSET, "model": "p3dx", "dist_conv": 0.5, "sonars": 8, "track": 0.4}
    units = fit("p3dx-sh", options)
    assert units.model.subclass == "p3dx" and "settings (model = p3dx)" in units.chosen_by
    assert (units.mm_per_unit, units.track, len(units.sonars)) == (0.5, 0.4, 8)
    rows = {row["name"]: row for row in units.describe()["factors"]}
    assert rows["dist_conv"]["source"] == "settings" and rows["vel_conv"]["source"] == "model"


def test_a_model_aria_does_not_know_is_read_in_millimetres_and_says_so():
    units = fit("mystery-bot", UNSET)
    assert units.mm_per_unit == 1.0
    assert "no file for" in units.chosen_by and "set model" in units.chosen_by


def test_bad_unit_settings_are_refused_when_the_driver_is_built():
    with pytest.raises(ValueError, match="no ARIA model 'p9x'"):
        PioneerRobot("pioneer+tcp://", model="p9x")
    with pytest.raises(ValueError, match="dist_conv must be greater than 0"):
        PioneerRobot("pioneer+tcp://", dist_conv=0)
    with pytest.raises(ValueError, match="front_bumpers must be a whole number"):
        PioneerRobot("pioneer+tcp://", front_bumpers=-1)


def test_unit_options_come_through_the_url():
    bot = rhal.connect("pioneer+tcp://127.0.0.1:8101?model=p3at&range_conv=0.268")
    assert bot.units.model.subclass == "p3at" and bot.units.mm_per_range_unit == 0.268
