"""The control lease: one program or one person moves the robot at a time."""

import pytest

from robots.lease import IDLE_SECONDS, ControlLease, Holder, LeaseHeld
from tests.rhal.conftest import ManualClock

ALICE_RUN = Holder("run", 7, "alice")
BOB_HAND = Holder("teleop", "chan-b", "bob")
STAFF = Holder("teleop", "chan-s", "teacher")


@pytest.fixture
def clock():
    return ManualClock()


@pytest.fixture
def lease(clock):
    return ControlLease(clock)


def test_the_first_to_drive_holds_it_and_others_are_told_who(lease):
    assert lease.acquire(ALICE_RUN) is True
    assert lease.acquire(ALICE_RUN) is False  # again: no change of hands
    with pytest.raises(LeaseHeld, match=r"controlled by alice's program \(run #7\)"):
        lease.acquire(BOB_HAND)
    assert lease.holds(7) and not lease.holds("chan-b")


def test_a_program_holds_until_it_ends_however_long(lease, clock):
    lease.acquire(ALICE_RUN)
    clock.advance(10 * IDLE_SECONDS)
    with pytest.raises(LeaseHeld):
        lease.acquire(BOB_HAND)
    assert lease.release(7) is True
    assert lease.acquire(BOB_HAND) is True


def test_a_person_who_leaves_the_controls_alone_lets_go(lease, clock):
    lease.acquire(BOB_HAND)
    clock.advance(IDLE_SECONDS - 1)
    lease.acquire(BOB_HAND)  # still driving: renewed
    clock.advance(IDLE_SECONDS - 1)
    with pytest.raises(LeaseHeld, match="bob, driving by hand"):
        lease.acquire(ALICE_RUN)
    clock.advance(1)
    assert lease.acquire(ALICE_RUN) is True


def test_staff_take_over_and_only_the_holder_releases(lease):
    lease.acquire(ALICE_RUN)
    assert lease.release("chan-b") is False
    assert lease.acquire(STAFF, take_over=True) is True
    assert lease.holder == STAFF
    assert lease.release(STAFF.key) is True and lease.holder is None
    assert lease.release(STAFF.key) is False


def test_an_emergency_stop_holds_it_from_everyone_until_resumed(lease):
    lease.acquire(ALICE_RUN)
    lease.estop("carol")
    assert lease.estopped and lease.holder.user == "carol"
    for who, kwargs in ((ALICE_RUN, {}), (STAFF, {"take_over": True})):
        with pytest.raises(LeaseHeld, match="the emergency stop carol pressed"):
            lease.acquire(who, **kwargs)
    assert lease.release(ALICE_RUN.key) is False and lease.release("estop") is False
    assert lease.end_estop() is True and lease.holder is None
    assert lease.end_estop() is False
    assert lease.acquire(ALICE_RUN) is True
