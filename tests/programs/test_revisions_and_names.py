"""What the revisions pages offer for the current revision, and examples' names."""

import pytest
from django.contrib.auth.models import User

from programs.models import Program

pytestmark = pytest.mark.django_db


@pytest.fixture
def alice(client):
    user = User.objects.create_user("alice", password="pw-alice-123")
    client.force_login(user)
    return user


def test_the_current_revision_is_not_offered_to_compare_with_itself(client, alice):
    program = Program.objects.create(owner=alice, name="hello", language="python")
    program.save_source("print('one')\n", alice)
    program.save_source("print('two')\n", alice)
    listing = client.get(f"/programs/{program.pk}/revisions/").content.decode()
    assert listing.count("Compare with current") == 1  # revision 1's row only
    current = client.get(f"/programs/{program.pk}/revisions/2/").content.decode()
    assert "This is the current revision" in current
    assert "Restore this revision" not in current and "Changes from revision" not in current
    older = client.get(f"/programs/{program.pk}/revisions/1/").content.decode()
    assert "Restore this revision" in older and "Changes from revision 1" in older


def test_a_reader_of_a_shared_program_is_not_offered_restore(client, alice):
    from programs.models import Share

    bob = User.objects.create_user("bob", password="pw-bob-123")
    program = Program.objects.create(owner=bob, name="bobs", language="python")
    program.save_source("print('one')\n", bob)
    program.save_source("print('two')\n", bob)
    Share.objects.create(program=program, user=alice)
    older = client.get(f"/programs/{program.pk}/revisions/1/").content.decode()
    assert "Changes from revision 1" in older and "Restore this revision" not in older
    page = client.get(f"/programs/{program.pk}/").content.decode()
    assert 'id="read-only-note"' in page and "bob shared this program with you" in page
    assert "readonly" in page.split('id="source"')[1].split(">")[0]


def test_example_names_have_no_doubled_brackets(alice):
    names = list(Program.objects.filter(owner=alice).values_list("name", flat=True))
    assert "Wall and turn (JavaScript)" in names
    assert not [name for name in names if "))" in name], names
