"""Import and export of all of a user's programs as a zip of plain files (and its manifest)."""

import io
import json
import re
import zipfile
from datetime import date

import pytest
from django.contrib.auth.models import User
from django.core.files.uploadedfile import SimpleUploadedFile
from django.template.loader import render_to_string
from django.test import Client, RequestFactory

from programs import archive
from programs.archive import ArchiveTooLarge, BadArchive, NotAZip, export_zip, import_zip
from programs.models import MAX_SOURCE_BYTES, Program
from robotide.models import ApiToken

pytestmark = pytest.mark.django_db


def make_user(name, *, staff=False, examples=True):
    user = User.objects.create_user(name, password=f"pw-{name}-123", is_staff=staff)
    if not examples:
        user.programs.all().delete()
    return user


def add_program(owner, name, language="python", source="print(1)\n", origin=""):
    program = Program.objects.create(owner=owner, name=name, language=language, origin=origin)
    program.save_source(source, owner)
    return program


def make_zip(files: dict, manifest=None) -> bytes:
    """files: archive name -> text or bytes; manifest: an object to store as manifest.json."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, content in files.items():
            zf.writestr(name, content)
        if manifest is not None:
            zf.writestr("manifest.json", json.dumps(manifest))
    return buffer.getvalue()


def opened(data: bytes) -> tuple[dict, dict]:
    """(files by name, the manifest) of a zip."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        files = {name: zf.read(name).decode() for name in zf.namelist()}
    return files, json.loads(files.pop("manifest.json"))


@pytest.fixture
def alice():
    return make_user("alice", examples=False)


@pytest.fixture
def bob():
    return make_user("bob")  # with the examples every new account gets


def sources(user) -> dict:
    return {p.name: (p.language, p.source) for p in Program.objects.filter(owner=user)}


# -- export --------------------------------------------------------------------------------------


def test_export_has_one_plain_file_per_program_and_a_manifest(alice):
    compass = add_program(alice, "Compass", source="a\n")
    compass.save_source("b\n", alice)
    add_program(alice, "Hello", "shell", "echo hi\n", origin="copied from bob")
    files, manifest = opened(export_zip(alice.programs.all()))
    assert files == {"compass.py": "b\n", "hello.sh": "echo hi\n"}
    assert manifest["format"] == "robotide-programs" and manifest["version"] == 1
    assert manifest["exported"][:10] == date.today().isoformat()
    entries = {e["file"]: e for e in manifest["programs"]}
    assert entries["compass.py"]["name"] == "Compass"
    assert entries["compass.py"]["language"] == "python"
    assert entries["compass.py"]["revisions"] == 2
    assert entries["hello.sh"]["origin"] == "copied from bob"
    assert entries["hello.sh"]["created"] == alice.programs.get(name="Hello").created.isoformat()
    assert set(entries["hello.sh"]) == {
        "name", "language", "file", "created", "updated", "revisions", "origin",
    }  # fmt: skip


def test_export_file_names_are_unique(alice):
    for name in ["My prog", "my-prog", "MY PROG!", "Ωμέγα", "manifest"]:
        add_program(alice, name)
    add_program(alice, "my prog sh", "shell")
    files, manifest = opened(export_zip(alice.programs.all()))
    assert set(files) == {
        "my-prog.py", "my-prog-2.py", "my-prog-3.py", "program.py", "manifest.py",
        "my-prog-sh.sh",
    }  # fmt: skip
    assert len({e["file"] for e in manifest["programs"]}) == 6


# -- import --------------------------------------------------------------------------------------


def test_round_trip_into_another_user(alice):
    add_program(alice, "Compass", source="import robot\nprint('ü')\n")
    add_program(alice, "Hello", "shell", "echo hi\n")
    add_program(alice, "Wall", "tcl", "puts wall\n")
    carol = make_user("carol", examples=False)
    report = import_zip(export_zip(alice.programs.all()), carol, filename="alice.zip")
    assert sources(carol) == sources(alice)
    assert {e.program.name for e in report.created} == {"Compass", "Hello", "Wall"}
    assert report.updated == [] and report.skipped == []
    for program in carol.programs.all():
        assert program.origin == "imported from alice.zip"
        assert program.revisions.get().author == carol
    assert alice.programs.count() == 3  # untouched


def test_names_taken_already_get_a_number(alice, bob):
    add_program(alice, "Compass", source="# alice's compass\n")
    bobs = bob.programs.get(name="Compass").source
    report = import_zip(export_zip(alice.programs.all()), bob)
    assert [e.program.name for e in report.created] == ["Compass (2)"]
    assert bob.programs.get(name="Compass").source == bobs
    assert bob.programs.get(name="Compass (2)").source == "# alice's compass\n"
    again = import_zip(export_zip(alice.programs.all()), bob)
    assert [e.program.name for e in again.created] == ["Compass (3)"]


def test_replace_adds_a_revision_and_keeps_the_history(alice):
    compass = add_program(alice, "Compass", source="old\n")
    add_program(alice, "Hello", "shell", "echo hi\n")
    files, manifest = opened(export_zip(alice.programs.all()))
    files["compass.py"] = "new\n"
    report = import_zip(make_zip(files, manifest), alice, replace=True)
    assert [(e.file, e.program.pk) for e in report.updated] == [("compass.py", compass.pk)]
    assert report.created == []
    assert [(s.file, s.why) for s in report.skipped] == [
        ("hello.sh", "the same as 'Hello' already")
    ]
    compass.refresh_from_db()
    assert compass.source == "new\n"
    assert [r.source for r in compass.revisions.all()] == ["new\n", "old\n"]
    assert alice.programs.count() == 2


def test_replace_creates_what_is_not_there(alice):
    report = import_zip(make_zip({"new.py": "1\n"}), alice, replace=True)
    assert [e.program.name for e in report.created] == ["new"]


def test_import_without_a_manifest_goes_by_the_extensions(alice):
    data = make_zip(
        {
            "wall.py": "print('wall')\r\n",
            "Turn.LUA": "print(1)\n",
            "notes.txt": "remember",
            "README": "hi",
            "bom.rb": "\ufeffputs 1\n".encode(),
            "latin1.py": "print('é')\n".encode("latin-1"),
            "nul.sh": b"echo \x00",
        }
    )
    report = import_zip(data, alice)
    assert sources(alice) == {
        "wall": ("python", "print('wall')\n"),
        "Turn": ("lua", "print(1)\n"),
        "bom": ("ruby", "puts 1\n"),
    }
    assert {s.file: s.why for s in report.skipped} == {
        "notes.txt": "no language has the extension '.txt'",
        "README": "no extension",
        "latin1.py": "not UTF-8 text",
        "nul.sh": "not text (it has NUL bytes)",
    }


def test_the_manifest_names_the_programs_and_files_it_does_not_list_are_placed_too(alice):
    manifest = {
        "format": "robotide-programs",
        "version": 1,
        "programs": [
            {"file": "a.txt", "name": "Nice name", "language": "perl"},
            {"file": "b.py", "name": "  ", "language": "cobol"},
            {"file": "c.txt", "name": "C", "language": "cobol"},
            {"file": "gone.py", "name": "Deleted since"},
        ],
    }
    data = make_zip({"a.txt": "print 1;\n", "b.py": "1\n", "c.txt": "", "new.sh": "ls\n"}, manifest)
    report = import_zip(data, alice)
    assert sources(alice) == {
        "Nice name": ("perl", "print 1;\n"),
        "b": ("python", "1\n"),
        "new": ("shell", "ls\n"),
    }
    assert {s.file: s.why for s in report.skipped} == {
        "c.txt": "unknown language 'cobol'",
        "gone.py": "listed in the manifest but not in the zip",
    }


def test_a_zipped_folder_is_looked_through(alice):
    files, manifest = {"robotide-alice/x.py": "1\n"}, {"programs": [{"file": "x.py", "name": "X"}]}
    data = make_zip(files | {"robotide-alice/manifest.json": json.dumps(manifest)})
    with zipfile.ZipFile(buffer := io.BytesIO(data), "a") as zf:
        zf.writestr("robotide-alice/", "")  # a folder entry, as zip tools add
        zf.writestr("__MACOSX/robotide-alice/._x.py", b"\x00\x05\x16\x07")
    import_zip(buffer.getvalue(), alice)
    assert sources(alice) == {"X": ("python", "1\n")}


def encrypted(data: bytes, name: str) -> bytes:
    """The zip with `name` flagged as encrypted (zipfile cannot write encrypted files)."""
    data = bytearray(data)
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as zf:
        data[zf.getinfo(name).header_offset + 6] |= 0x1  # the local header's flags
    central = data.rindex(name.encode()) - 46  # the central directory comes last
    assert data[central : central + 4] == b"PK\x01\x02"
    data[central + 8] |= 0x1
    return bytes(data)


def test_oversized_and_odd_files_are_reported_and_the_rest_imported(alice):
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("ok.py", "1\n")
        zf.writestr("big.py", "#" * (MAX_SOURCE_BYTES + 1))
        link = zipfile.ZipInfo("link.py")
        link.external_attr = 0o120777 << 16
        zf.writestr(link, "/etc/passwd")
        zf.writestr("secret.py", "1\n")  # marked encrypted below
        with pytest.warns(UserWarning, match="Duplicate name"):
            zf.writestr("ok.py", "2\n")  # the same name again
    report = import_zip(encrypted(buffer.getvalue(), "secret.py"), alice)
    assert sources(alice) == {"ok": ("python", "1\n")}
    assert {s.file: s.why for s in report.skipped} == {
        "big.py": "larger than 512 KB, the most a program may be",
        "link.py": "a symbolic link, not a file",
        "secret.py": "encrypted",
        "ok.py": "in the zip twice: the first one counts",
    }


def test_an_empty_zip_imports_nothing_and_says_so(alice):
    report = import_zip(make_zip({}), alice)
    assert report.as_dict() == {"created": [], "updated": [], "skipped": []}


def damaged_member(compression=zipfile.ZIP_DEFLATED) -> bytes:
    """A zip whose second file is damaged: the first was imported by then."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression) as zf:
        zf.writestr("first.py", "1\n")
        zf.writestr("second.py", "x" * 1000)
    data = bytearray(buffer.getvalue())
    at = data.index(b"second.py") + len("second.py") + 2  # in its (compressed) data
    data[at] ^= 0xFF
    return bytes(data)


def bomb() -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for n in range(6):  # 60 MB of zeros in a zip of a few hundred KB
            zf.writestr(f"zeros{n}.py", bytes(10 * 1024 * 1024))
    return buffer.getvalue()


def unsafe(name: str) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        zf.writestr("fine.py", "1\n")
        zf.writestr(zipfile.ZipInfo(name), "print('escaped')\n")  # ZipInfo keeps the name as is
    return buffer.getvalue()


BAD_ZIPS = {
    "not a zip": (lambda: b"print('hello')\n", NotAZip, "Not a zip file"),
    "empty": (lambda: b"", NotAZip, "Not a zip file"),
    "cut short": (lambda: make_zip({"a.py": "1\n" * 1000})[:-30], NotAZip, "Not a zip file"),
    "damaged": (damaged_member, NotAZip, "The zip is damaged"),
    "a checksum that fails": (
        lambda: damaged_member(zipfile.ZIP_STORED),
        NotAZip,
        "The zip is damaged (Bad CRC-32 for file 'second.py')",
    ),
    "a manifest nested too deep": (
        lambda: make_zip({"manifest.json": "[" * 100_000 + "]" * 100_000}),
        BadArchive,
        "manifest.json is unusable",
    ),
    "a zip bomb": (bomb, ArchiveTooLarge, "more than 50 MB uncompressed"),
    "too many files": (
        lambda: make_zip({f"p{n}.py": "" for n in range(1001)}),
        ArchiveTooLarge,
        "more than 1000 files",
    ),
    "an absolute path": (lambda: unsafe("/etc/cron.d/x.py"), BadArchive, "an absolute path"),
    "a Windows path": (lambda: unsafe("C:\\x.py"), BadArchive, "an absolute path"),
    "..": (lambda: unsafe("../../x.py"), BadArchive, "climbs out of it"),
    "..\\": (lambda: unsafe("a\\..\\..\\x.py"), BadArchive, "climbs out of it"),
    "nested folders": (
        lambda: make_zip({"a.py": "1\n", "lib/b.py": "2\n"}),
        BadArchive,
        "'lib/b.py' is in a folder: put the program files at the top of the zip",
    ),
    "a manifest that is not JSON": (
        lambda: make_zip({"a.py": "1\n", "manifest.json": "{nope"}),
        BadArchive,
        "manifest.json is unusable",
    ),
    "someone else's manifest": (
        lambda: make_zip({"a.py": "1\n"}, manifest={"format": "npm"}),
        BadArchive,
        "not a robotide manifest",
    ),
    "a newer format": (
        lambda: make_zip({"a.py": "1\n"}, manifest={"version": 99}),
        BadArchive,
        "made by a newer robotide",
    ),
    "programs not a list": (
        lambda: make_zip({"a.py": "1\n"}, manifest={"programs": {"a.py": "python"}}),
        BadArchive,
        '"programs" must be a list',
    ),
}


@pytest.mark.parametrize("case", BAD_ZIPS)
def test_bad_zips_are_refused_clearly_and_nothing_is_imported(alice, case):
    make, error, message = BAD_ZIPS[case]
    with pytest.raises(error, match=re.escape(message)):
        import_zip(make(), alice)
    assert alice.programs.count() == 0


def test_a_zip_larger_than_the_cap_is_not_even_opened(alice, monkeypatch):
    monkeypatch.setattr(archive, "MAX_TOTAL_BYTES", 100)
    with pytest.raises(ArchiveTooLarge, match="larger than"):
        import_zip(make_zip({"a.py": "#" * 200}, {"programs": []}) + b"x" * 100, alice)


# -- API -----------------------------------------------------------------------------------------


def api_client(user) -> Client:
    _, token = ApiToken.issue(user)
    return Client(HTTP_AUTHORIZATION=f"Bearer {token}")


def test_api_export_is_the_callers_own_programs(alice):
    add_program(alice, "Mine")
    teacher = make_user("teacher", staff=True, examples=False)
    add_program(teacher, "Teacher's")
    response = api_client(teacher).get("/api/programs/export")
    assert response.status_code == 200 and response["Content-Type"] == "application/zip"
    today = date.today().isoformat()
    assert response["Content-Disposition"] == (
        f'attachment; filename="robotide-teacher-{today}.zip"'
    )
    files, manifest = opened(response.content)
    assert files == {"teachers.py": "print(1)\n"}
    assert api_client(alice).get("/api/programs").status_code == 200  # staff sees more there


def test_api_export_and_import_need_credentials(alice):
    assert Client().get("/api/programs/export").status_code == 401
    upload = SimpleUploadedFile("a.zip", make_zip({"a.py": "1\n"}))
    assert Client().post("/api/programs/import", {"file": upload}).status_code == 401
    assert Program.objects.count() == 0


def test_api_import_takes_a_multipart_zip(alice):
    add_program(alice, "a", source="old\n")
    client = api_client(alice)
    data = make_zip({"a.py": "new\n", "b.sh": "ls\n", "c.txt": ""})
    upload = SimpleUploadedFile("mine.zip", data, content_type="application/zip")
    response = client.post("/api/programs/import", {"file": upload})
    assert response.status_code == 200
    body = response.json()
    a2, b = alice.programs.get(name="a (2)"), alice.programs.get(name="b")
    assert body == {
        "created": [
            {"id": a2.pk, "name": "a (2)", "file": "a.py"},
            {"id": b.pk, "name": "b", "file": "b.sh"},
        ],
        "updated": [],
        "skipped": [{"file": "c.txt", "why": "no language has the extension '.txt'"}],
    }
    assert b.origin == "imported from mine.zip"
    upload = SimpleUploadedFile("mine.zip", data)
    replaced = client.post("/api/programs/import", {"file": upload, "replace": "true"}).json()
    assert [p["name"] for p in replaced["updated"]] == ["a"]
    assert alice.programs.get(name="a").revisions.count() == 2


@pytest.mark.parametrize(
    ("data", "status", "detail"),
    [
        (b"not a zip", 400, "Not a zip file"),
        (make_zip({f"p{n}.py": "" for n in range(1001)}), 413, "more than 1000 files"),
        (make_zip({"../x.py": "1\n"}), 422, "climbs out of it"),
    ],
)
def test_api_bad_zips_get_a_status_and_a_detail(alice, data, status, detail):
    upload = SimpleUploadedFile("bad.zip", data)
    response = api_client(alice).post("/api/programs/import", {"file": upload})
    assert response.status_code == status and detail in response.json()["detail"]
    assert alice.programs.count() == 0


def test_api_import_without_a_file_is_a_validation_error(alice):
    response = api_client(alice).post("/api/programs/import", {})
    assert response.status_code == 422


def test_api_schema_documents_the_zip(client):
    def no_key_twice(pairs):
        keys = [key for key, _ in pairs]
        assert len(keys) == len(set(keys)), keys
        return dict(pairs)

    text = client.get("/api/openapi.json").content
    paths = json.loads(text, object_pairs_hook=no_key_twice)["paths"]
    export = paths["/api/programs/export"]["get"]["responses"]["200"]
    assert "application/zip" in export["content"]
    imported = paths["/api/programs/import"]["post"]
    assert "multipart/form-data" in imported["requestBody"]["content"]
    assert {"200", "400", "413", "422"} <= set(imported["responses"])


# -- pages ---------------------------------------------------------------------------------------


@pytest.fixture
def signed_in(client, alice):
    client.force_login(alice)
    return client


def test_page_export_downloads_the_zip(signed_in, alice):
    add_program(alice, "Mine")
    response = signed_in.get("/programs/export")
    assert response.status_code == 200 and response["Content-Type"] == "application/zip"
    assert "robotide-alice-" in response["Content-Disposition"]
    assert opened(response.content)[0] == {"mine.py": "print(1)\n"}


def test_pages_require_sign_in(client):
    assert client.get("/programs/export").status_code == 302
    assert client.post("/programs/import").status_code == 302


def test_page_import_reports_in_messages(signed_in, alice):
    data = make_zip({"a.py": "1\n", "b.txt": ""})
    upload = SimpleUploadedFile("mine.zip", data)
    response = signed_in.post("/programs/import", {"file": upload}, follow=True)
    page = response.content.decode()
    assert response.redirect_chain == [("/programs/", 302)]
    assert "Imported mine.zip: 1 created, 0 updated, 1 skipped." in page
    assert "Skipped b.txt (no language has the extension &#x27;.txt&#x27;)." in page
    assert list(alice.programs.values_list("name", flat=True)) == ["a"]


def test_page_import_of_a_bad_zip_says_nothing_was_imported(signed_in, alice):
    upload = SimpleUploadedFile("mine.zip", b"nope")
    page = signed_in.post("/programs/import", {"file": upload}, follow=True).content.decode()
    assert "Nothing was imported from mine.zip: Not a zip file" in page
    assert "Choose a zip file" in signed_in.post("/programs/import", follow=True).content.decode()
    assert signed_in.get("/programs/import").status_code == 405
    assert alice.programs.count() == 0


def test_page_import_replace_checkbox(signed_in, alice):
    add_program(alice, "a", source="old\n")
    upload = SimpleUploadedFile("mine.zip", make_zip({"a.py": "new\n"}))
    signed_in.post("/programs/import", {"file": upload, "replace": "true"})
    assert alice.programs.get().source == "new\n"


def test_the_fragment_links_export_and_posts_import_with_csrf(alice):
    request = RequestFactory().get("/programs/")
    request.user = alice
    html = render_to_string("programs/_archive.html", request=request)
    assert 'href="/programs/export"' in html and 'action="/programs/import"' in html
    assert 'enctype="multipart/form-data"' in html and "csrfmiddlewaretoken" in html
    assert 'name="file"' in html and 'name="replace" value="true"' in html
