"""A real OpenID Connect provider for the sign-in tests: node's oidc-provider (tests/oidc/), on a
free port, its accounts in a JSON file the tests may change while it runs."""

import json
import os
import shutil
import subprocess
import time
from pathlib import Path
from urllib.parse import urljoin

import httpx
import pytest

from tests.appliance import free_port
from tests.conftest import in_ci

HERE = Path(__file__).resolve().parent / "oidc"
CLIENT_ID, CLIENT_SECRET = "robotide", "client-secret-for-tests"

# login -> password, claims (what a school's provider would say of its people)
ACCOUNTS = {
    "ana": {
        "password": "ana-pass-1",
        "claims": {
            "preferred_username": "ana",
            "given_name": "Ana",
            "family_name": "Aluna",
            "email": "ana@uni.test",
            "groups": ["class-robotics1", "chess-club"],
            "roles": ["student"],
        },
    },
    "tom": {
        "password": "tom-pass-1",
        "claims": {
            "preferred_username": "tom",
            "given_name": "Tom",
            "family_name": "Teacher",
            "email": "tom@uni.test",
            "groups": ["class-robotics1"],
            "roles": ["teacher"],
        },
    },
    "sia": {
        "password": "sia-pass-1",
        "claims": {
            "preferred_username": "sia",
            "email": "someone-else@uni.test",
            "email_verified": False,
            "roles": ["staff"],
        },
    },
    "dora": {
        "password": "dora-pass-1",
        "claims": {"preferred_username": "dora", "email": "dora@uni.test", "groups": []},
    },
    # Says it is "admin": a local account's name, which it must never get.
    "mallory": {
        "password": "mallory-pass-1",
        "claims": {"preferred_username": "admin", "email": "admin@uni.test"},
    },
}


def _unavailable(why: str):
    if in_ci():
        pytest.fail(f"the OpenID Connect test provider is needed in CI: {why}", pytrace=False)
    pytest.skip(why)


class Provider:
    def __init__(self, where: Path, redirect_uris: list[str], logout_uris: list[str]):
        self.where = where
        self.port = free_port()
        self.issuer = f"http://127.0.0.1:{self.port}"
        self.discovery_url = f"{self.issuer}/.well-known/openid-configuration"
        self.accounts_file = where / "accounts.json"
        self.accounts = json.loads(json.dumps(ACCOUNTS))
        self.redirect_uris, self.logout_uris = redirect_uris, logout_uris

    def save_accounts(self) -> None:
        tmp = self.accounts_file.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.accounts))
        tmp.replace(self.accounts_file)  # never half-written under the provider's read

    def start(self) -> "Provider":
        node = shutil.which("node")
        if not node:
            _unavailable("node is not installed (Debian: nodejs npm)")
        version = subprocess.run([node, "--version"], capture_output=True, text=True).stdout
        if int(version.lstrip("v").split(".")[0] or 0) < 20:
            _unavailable(f"oidc-provider 9 needs Node.js 20 or later, not {version.strip()}")
        if not (HERE / "node_modules" / "oidc-provider").exists():
            npm = shutil.which("npm") or _unavailable("npm is not installed (Debian: npm)")
            subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=HERE, check=True)
        self.save_accounts()
        env = {
            **os.environ,
            "PORT": str(self.port),
            "CLIENT_ID": CLIENT_ID,
            "CLIENT_SECRET": CLIENT_SECRET,
            "REDIRECT_URIS": ",".join(self.redirect_uris),
            "POST_LOGOUT_REDIRECT_URIS": ",".join(self.logout_uris),
            "ACCOUNTS": str(self.accounts_file),
        }
        self.log = open(self.where / "provider.log", "w")  # noqa: SIM115
        self.process = subprocess.Popen(
            [node, str(HERE / "provider.js")], env=env, stdout=self.log, stderr=self.log
        )
        deadline = time.monotonic() + 20
        while True:
            try:
                if httpx.get(self.discovery_url, timeout=2).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                _unavailable(f"the provider did not start:\n{self.logs()}")
            time.sleep(0.1)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(10)
        self.log.close()

    def logs(self) -> str:
        return (self.where / "provider.log").read_text()

    def env(self) -> dict[str, str]:
        """ROBOTIDE_OIDC_* for robotide to use this provider."""
        return {
            "ROBOTIDE_OIDC_DISCOVERY_URL": self.discovery_url,
            "ROBOTIDE_OIDC_CLIENT_ID": CLIENT_ID,
            "ROBOTIDE_OIDC_CLIENT_SECRET": CLIENT_SECRET,
            "ROBOTIDE_OIDC_NAME": "Uni Login",
            "ROBOTIDE_OIDC_SCOPES": "openid email profile groups",
            "ROBOTIDE_OIDC_CLASSES_CLAIM": "groups",
            "ROBOTIDE_OIDC_CLASS_PATTERN": "class-*",
            "ROBOTIDE_OIDC_TEACHER_CLAIM": "roles",
            "ROBOTIDE_OIDC_TEACHER_VALUE": "teacher",
            "ROBOTIDE_OIDC_STAFF_CLAIM": "roles",
            "ROBOTIDE_OIDC_STAFF_VALUE": "staff",
        }

    def sign_in_elsewhere(self, url: str, login: str, password: str) -> str | None:
        """A browser of its own (httpx) at this provider's authorization ``url``, signing in as
        ``login``: the URL the provider sends it back to, or None when the provider refuses
        (asks for the sign-in again)."""
        posted = False
        with httpx.Client(timeout=10) as browser:
            for _ in range(12):
                response = browser.get(url)
                if response.is_redirect:
                    url = urljoin(url, response.headers["location"])
                    if not url.startswith(self.issuer):
                        return url
                    continue
                assert 'name="login"' in response.text, response.text
                if posted:
                    return None
                form = {"prompt": "login", "login": login, "password": password}
                url = urljoin(url, browser.post(url, data=form).headers["location"])
                posted = True
        raise AssertionError("the provider never sent the browser back")
