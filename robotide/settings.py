"""One settings module, read from the environment with embedded defaults.

Embedded mode (nothing set): SQLite and data under ``ROBOTIDE_DATA`` (default ``./var``),
in-memory channel layer, the robot agent inside the web server process.
Fleet mode: ``DATABASE_URL`` and ``REDIS_URL`` switch to PostgreSQL and Redis.
"""

import ipaddress
import os
import secrets
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

import dj_database_url
from django.core.exceptions import ImproperlyConfigured
from django.utils.translation import gettext_lazy

from runbox.share import Share

BASE_DIR = Path(__file__).resolve().parent.parent


def env_bool(name: str, default: bool) -> bool:
    value = os.environ.get(name)
    if value is None or value == "":
        return default
    if value.lower() in ("1", "true", "yes", "on"):
        return True
    if value.lower() in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"{name} must be a boolean (1/0, true/false), not {value!r}")


def env_int(name: str, default: int) -> int:
    value = os.environ.get(name)
    if value is None or value == "":
        return default
    try:
        return int(value)
    except ValueError:
        raise ValueError(f"{name} must be an integer, not {value!r}") from None


def env_float(name: str, default: float) -> float:
    value = os.environ.get(name)
    if value is None or value == "":
        return default
    try:
        result = float(value)
    except ValueError:
        result = -1.0
    if not result > 0:
        raise ValueError(f"{name} must be a number of seconds above 0, not {value!r}")
    return result


def env_list(name: str, default: list[str]) -> list[str]:
    value = os.environ.get(name)
    if not value:
        return default
    return [item.strip() for item in value.split(",") if item.strip()]


DATA_DIR = Path(os.environ.get("ROBOTIDE_DATA") or BASE_DIR / "var").resolve()
DATA_DIR.mkdir(parents=True, exist_ok=True)
RUNS_DIR = DATA_DIR / "runs"


def _secret_key() -> str:
    # Generated once per data directory, so sessions survive restarts without a configured key.
    if os.environ.get("SECRET_KEY"):
        return os.environ["SECRET_KEY"]
    path = DATA_DIR / "secret_key"
    if not path.exists():
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(secrets.token_urlsafe(50))
    return path.read_text().strip()


SECRET_KEY = _secret_key()
DEBUG = env_bool("DEBUG", False)
ALLOWED_HOSTS = env_list("ALLOWED_HOSTS", ["*"])
CSRF_TRUSTED_ORIGINS = env_list("CSRF_TRUSTED_ORIGINS", [])

INSTALLED_APPS = [
    "django.contrib.admin",
    "django.contrib.auth",
    "django.contrib.contenttypes",
    "django.contrib.sessions",
    "django.contrib.messages",
    "django.contrib.staticfiles",
    "django_htmx",
    "channels",
    "robotide",
    "robots",
    "programs",
    "runlogs",
    "worlds",
    "classroom",
]

MIDDLEWARE = [
    "django.middleware.security.SecurityMiddleware",
    "whitenoise.middleware.WhiteNoiseMiddleware",
    "django.contrib.sessions.middleware.SessionMiddleware",
    "django.middleware.locale.LocaleMiddleware",
    "django.middleware.common.CommonMiddleware",
    "django.middleware.csrf.CsrfViewMiddleware",
    "django.contrib.auth.middleware.AuthenticationMiddleware",
    "robotide.language.UserLanguageMiddleware",
    "django.contrib.messages.middleware.MessageMiddleware",
    "classroom.middleware.OneTimePasswordMiddleware",  # a teacher's password changed first
    "django.middleware.clickjacking.XFrameOptionsMiddleware",
    "django_htmx.middleware.HtmxMiddleware",
]

ROOT_URLCONF = "robotide.urls"
ASGI_APPLICATION = "robotide.asgi.application"

TEMPLATES = [
    {
        "BACKEND": "django.template.backends.django.DjangoTemplates",
        "DIRS": [BASE_DIR / "templates"],
        "APP_DIRS": True,
        "OPTIONS": {
            "context_processors": [
                "django.template.context_processors.request",
                "django.contrib.auth.context_processors.auth",
                "django.contrib.messages.context_processors.messages",
            ],
            "builtins": ["robotide.templatetags.robotide"],
        },
    },
]

DATABASES = {
    "default": dj_database_url.config(
        default=f"sqlite:///{DATA_DIR / 'robotide.sqlite3'}",
        conn_max_age=600,
        conn_health_checks=True,
    )
}
if DATABASES["default"]["ENGINE"].endswith("sqlite3"):
    # WAL lets the agent write run states while pages read; the timeout rides out short locks.
    DATABASES["default"]["OPTIONS"] = {
        "timeout": 20,
        "init_command": "PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;",
        "transaction_mode": "IMMEDIATE",
    }

DEFAULT_AUTO_FIELD = "django.db.models.BigAutoField"


def channel_namespace(url: str) -> str:
    """Redis's publish/subscribe channels are the server's, whatever the database: robotides
    given other databases of one server (REDIS_URL .../3) would take each other's messages.
    The database's number goes into every channel's and group's name ("db3."; none for 0)."""
    parts = urlsplit(url)
    path_db = "" if parts.scheme == "unix" else parts.path.strip("/")
    db = path_db or dict(parse_qsl(parts.query)).get("db", "")
    return "" if db in ("", "0") else f"db{db}."


def redis_layer_config(url: str) -> dict:
    """The Redis channel layer's settings for REDIS_URL `url`."""
    return {"hosts": [{"address": url}], "prefix": f"asgi{channel_namespace(url)}"}


REDIS_URL = os.environ.get("REDIS_URL", "")
CHANNEL_NAMESPACE = channel_namespace(REDIS_URL)  # robots.models.agent_channel and the layer's
if REDIS_URL:
    # Redis publish/subscribe: a message to a group goes out once and each process that has
    # members hands it to them, so a worker with 50 viewers of a run's log takes 1 message, not
    # 50 (channels_redis's list-based layer queued a copy per viewer, and on a busy machine its
    # inboxes filled up and dropped log lines). Delivery is at most once, to whoever listens:
    # a run.start that no agent heard is failed by robots.presence after AGENT_START_TIMEOUT.
    CHANNEL_LAYERS = {
        "default": {
            "BACKEND": "channels_redis.pubsub.RedisPubSubChannelLayer",
            "CONFIG": redis_layer_config(REDIS_URL),
        }
    }
else:
    CHANNEL_LAYERS = {
        "default": {"BACKEND": "channels.layers.InMemoryChannelLayer", "CONFIG": {"capacity": 1000}}
    }

AUTH_PASSWORD_VALIDATORS = [
    {"NAME": "django.contrib.auth.password_validation.UserAttributeSimilarityValidator"},
    {"NAME": "django.contrib.auth.password_validation.MinimumLengthValidator"},
    {"NAME": "django.contrib.auth.password_validation.CommonPasswordValidator"},
]
LOGIN_URL = "login"
LOGIN_REDIRECT_URL = "program-list"
LOGOUT_REDIRECT_URL = "login"

# -- Web security (CSP, HTTPS, cookies, login throttling, request size) -----------------------
# A session ends this many hours after signing in, whether or not the browser is closed.
SESSION_COOKIE_AGE = env_int("ROBOTIDE_SESSION_HOURS", 12) * 3600
SESSION_COOKIE_HTTPONLY = True
SESSION_COOKIE_SAMESITE = "Lax"
CSRF_COOKIE_SAMESITE = "Lax"
SECURE_CONTENT_TYPE_NOSNIFF = True
SECURE_REFERRER_POLICY = "same-origin"
X_FRAME_OPTIONS = "DENY"

HTTPS = env_bool("ROBOTIDE_HTTPS", False)
if HTTPS:
    SESSION_COOKIE_SECURE = True
    CSRF_COOKIE_SECURE = True
    SECURE_HSTS_SECONDS = 365 * 24 * 3600
    SECURE_HSTS_INCLUDE_SUBDOMAINS = True
    SECURE_SSL_REDIRECT = env_bool("ROBOTIDE_HTTPS_REDIRECT", False)
BEHIND_PROXY = env_bool("ROBOTIDE_BEHIND_PROXY", False)
if BEHIND_PROXY:
    # Only behind a proxy that sets (not forwards) the header: otherwise clients could claim HTTPS.
    SECURE_PROXY_SSL_HEADER = ("HTTP_X_FORWARDED_PROTO", "https")

# No inline script or style anywhere: pages load only our own static files. Program drawings
# are data: images. robotide.security adds this host's ws: or wss: to connect-src for browsers
# whose 'self' does not cover websockets (Safari before 15.4).
SELF, NONE = "'self'", "'none'"
CONTENT_SECURITY_POLICY = {
    "DIRECTIVES": {
        "default-src": [SELF],
        "script-src": [SELF],
        "style-src": [SELF],
        "img-src": [SELF, "data:"],
        "connect-src": [SELF],
        "frame-ancestors": [NONE],
        "object-src": [NONE],
        "base-uri": [SELF],
        "form-action": [SELF],
    }
}
# "ninja" serves the API docs from our static files (no CDN, no inline script).
INSTALLED_APPS += ["csp", "ninja"]
MIDDLEWARE.insert(
    MIDDLEWARE.index("django.middleware.security.SecurityMiddleware") + 1,
    "robotide.security.RequestSizeLimitMiddleware",
)
MIDDLEWARE.insert(
    MIDDLEWARE.index("django.middleware.security.SecurityMiddleware") + 1,
    "robotide.security.CSPMiddleware",
)

# Programs are at most 512 KB (programs.models.MAX_SOURCE_BYTES); a form or JSON body carrying
# one grows by escaping (%XX, \uXXXX). Larger requests are refused with 413 before being read.
MAX_REQUEST_BYTES = env_int("ROBOTIDE_MAX_REQUEST_KB", 2048) * 1024
DATA_UPLOAD_MAX_MEMORY_SIZE = MAX_REQUEST_BYTES
FILE_UPLOAD_MAX_MEMORY_SIZE = MAX_REQUEST_BYTES
DATA_UPLOAD_MAX_NUMBER_FIELDS = 400  # the admin's bulk actions post one field per row
DATA_UPLOAD_MAX_NUMBER_FILES = 10

# Blocks are made into Python and compiled by worker processes (programs.blocks_worker), never
# in the server or an agent: at most BLOCKS_WORKERS at once, each within an address space of
# BLOCKS_WORKER_MEMORY_MB, and BLOCKS_WORKER_SECONDS of CPU and of wall time a program.
BLOCKS_WORKERS = env_int("ROBOTIDE_BLOCKS_WORKERS", 2)
# Blocks at programs.blocks' caps took under 100 MB of address space here.
BLOCKS_WORKER_MEMORY_MB = env_int("ROBOTIDE_BLOCKS_WORKER_MEMORY_MB", 256)
BLOCKS_WORKER_SECONDS = env_int("ROBOTIDE_BLOCKS_WORKER_SECONDS", 10)

# Failed sign-ins within `window_seconds` lock a (user name, address) pair after `failures`, an
# address after `address_failures` (more: a lab shares one address), for `lock_seconds`.
LOGIN_THROTTLE = {
    "failures": env_int("ROBOTIDE_LOGIN_FAILURES", 5),
    "address_failures": env_int("ROBOTIDE_LOGIN_ADDRESS_FAILURES", 50),
    "window_seconds": env_int("ROBOTIDE_LOGIN_WINDOW_SECONDS", 900),
    "lock_seconds": env_int("ROBOTIDE_LOGIN_LOCK_SECONDS", 300),
}
AUTHENTICATION_BACKENDS = ["robotide.security.ThrottledModelBackend"]


def ldap_settings() -> dict:
    """django-auth-ldap's AUTH_LDAP_* settings from ROBOTIDE_LDAP_*; empty when the URI is unset.

    Local accounts (admins, guests) are tried first; the directory is asked on every sign-in,
    so an account removed there can no longer sign in. Imported only when configured: python-ldap
    is a C extension a machine without a directory need not load.
    """
    uri = os.environ.get("ROBOTIDE_LDAP_URI", "")
    if not uri:
        return {}
    try:
        import ldap
        from django_auth_ldap import config
    except ImportError as exc:
        raise ImproperlyConfigured(
            "ROBOTIDE_LDAP_URI is set but django-auth-ldap is not installed: "
            "scripts/install-build-deps.sh, then .venv/bin/pip install -e '.[ldap]'"
        ) from exc

    def required(name: str) -> str:
        value = os.environ.get(name, "")
        if not value:
            raise ValueError(f"{name} must be set when ROBOTIDE_LDAP_URI is")
        return value

    attrs = {}
    for pair in env_list(
        "ROBOTIDE_LDAP_ATTRS", ["first_name=givenName", "last_name=sn", "email=mail"]
    ):
        field, _, attr = pair.partition("=")
        if field.strip() not in ("first_name", "last_name", "email") or not attr.strip():
            raise ValueError(
                f"ROBOTIDE_LDAP_ATTRS: {pair!r} is not first_name=, last_name= or email=<attribute>"
            )
        attrs[field.strip()] = attr.strip()
    group_types = {
        "groupOfNames": config.GroupOfNamesType,
        "groupOfUniqueNames": config.GroupOfUniqueNamesType,
        "posixGroup": config.PosixGroupType,
        "activeDirectory": config.ActiveDirectoryGroupType,
        "nestedActiveDirectory": config.NestedActiveDirectoryGroupType,
    }
    group_type = os.environ.get("ROBOTIDE_LDAP_GROUP_TYPE") or "groupOfNames"
    if group_type not in group_types:
        raise ValueError(f"ROBOTIDE_LDAP_GROUP_TYPE must be one of {', '.join(group_types)}")
    options = {ldap.OPT_REFERRALS: 0, ldap.OPT_NETWORK_TIMEOUT: 10, ldap.OPT_TIMEOUT: 10}
    if os.environ.get("ROBOTIDE_LDAP_CA_FILE"):
        options[ldap.OPT_X_TLS_CACERTFILE] = os.environ["ROBOTIDE_LDAP_CA_FILE"]
        options[ldap.OPT_X_TLS_NEWCTX] = 0  # last: makes the TLS options above take effect
    result = {
        "AUTH_LDAP_SERVER_URI": uri,
        "AUTH_LDAP_BIND_DN": os.environ.get("ROBOTIDE_LDAP_BIND_DN", ""),
        "AUTH_LDAP_BIND_PASSWORD": os.environ.get("ROBOTIDE_LDAP_BIND_PASSWORD", ""),
        "AUTH_LDAP_START_TLS": env_bool("ROBOTIDE_LDAP_START_TLS", False),
        "AUTH_LDAP_CONNECTION_OPTIONS": options,
        "AUTH_LDAP_USER_SEARCH": config.LDAPSearch(
            required("ROBOTIDE_LDAP_USER_BASE"),
            ldap.SCOPE_SUBTREE,
            os.environ.get("ROBOTIDE_LDAP_USER_FILTER") or "(uid=%(user)s)",
        ),
        "AUTH_LDAP_USER_ATTR_MAP": attrs,
        "AUTH_LDAP_ALWAYS_UPDATE_USER": True,
        # Classes, teachers and staff (robotide.directory): from groups under this base.
        "AUTH_LDAP_GROUP_TYPE": group_types[group_type](),
        "ROBOTIDE_LDAP_CLASS_FILTER": os.environ.get("ROBOTIDE_LDAP_CLASS_FILTER", ""),
        "ROBOTIDE_LDAP_TEACHER_FILTER": os.environ.get("ROBOTIDE_LDAP_TEACHER_FILTER", ""),
    }
    group_base = os.environ.get("ROBOTIDE_LDAP_GROUP_BASE", "")
    if group_base:
        result["AUTH_LDAP_GROUP_SEARCH"] = config.LDAPSearch(group_base, ldap.SCOPE_SUBTREE)
    elif result["ROBOTIDE_LDAP_CLASS_FILTER"] or result["ROBOTIDE_LDAP_TEACHER_FILTER"]:
        raise ValueError("ROBOTIDE_LDAP_GROUP_BASE must be set for classes and teachers")
    if os.environ.get("ROBOTIDE_LDAP_STAFF_GROUP"):
        result["AUTH_LDAP_USER_FLAGS_BY_GROUP"] = {
            "is_staff": os.environ["ROBOTIDE_LDAP_STAFF_GROUP"]
        }
    return result


LDAP = ldap_settings()
if LDAP:
    globals().update(LDAP)
    # After the local accounts; each refuses a locked-out sign-in (security.ThrottledBackend).
    AUTHENTICATION_BACKENDS = [*AUTHENTICATION_BACKENDS, "robotide.directory.DirectoryBackend"]


def oidc_settings() -> dict:
    """Sign-in with an OpenID Connect provider (robotide.oidc) from ROBOTIDE_OIDC_*; empty when
    the discovery URL is unset. The provider is not asked here: its discovery document is read
    on the first sign-in, so a provider that is down cannot stop the start."""
    discovery = os.environ.get("ROBOTIDE_OIDC_DISCOVERY_URL", "")
    if not discovery:
        stray = sorted(n for n in os.environ if n.startswith("ROBOTIDE_OIDC_") and os.environ[n])
        if stray:
            raise ImproperlyConfigured(
                f"{', '.join(stray)} set but not ROBOTIDE_OIDC_DISCOVERY_URL: set it (the "
                "provider's .well-known/openid-configuration) or unset them"
            )
        return {}
    if not os.environ.get("ROBOTIDE_OIDC_CLIENT_ID"):
        raise ImproperlyConfigured(
            "ROBOTIDE_OIDC_CLIENT_ID must be set when ROBOTIDE_OIDC_DISCOVERY_URL is"
        )
    well_known = "/.well-known/openid-configuration"
    if not discovery.rstrip("/").endswith(well_known):
        discovery = discovery.rstrip("/") + well_known  # the issuer's URL was given
    claims = {"username": "preferred_username", "first_name": "given_name",
              "last_name": "family_name", "email": "email"}  # fmt: skip
    for pair in env_list("ROBOTIDE_OIDC_ATTRS", []):
        field, _, claim = (part.strip() for part in pair.partition("="))
        if field not in claims or not claim:
            raise ImproperlyConfigured(
                f"ROBOTIDE_OIDC_ATTRS: {pair!r} is not username=, first_name=, last_name= or "
                "email=<claim>"
            )
        claims[field] = claim
    scopes = os.environ.get("ROBOTIDE_OIDC_SCOPES") or "openid email profile"
    if "openid" not in scopes.split():
        raise ImproperlyConfigured(
            f"ROBOTIDE_OIDC_SCOPES must include openid (no ID token without it): {scopes!r}"
        )
    if os.environ.get("ROBOTIDE_OIDC_CLASSES_CLAIM") and not os.environ.get(
        "ROBOTIDE_OIDC_CLASS_PATTERN"
    ):
        # Users may name their own groups at many providers: which are classes is said here.
        raise ImproperlyConfigured(
            "ROBOTIDE_OIDC_CLASS_PATTERN must be set when ROBOTIDE_OIDC_CLASSES_CLAIM is: which "
            "of the claim's groups are classes (a shell pattern, e.g. robotics-*)"
        )
    for role in ("TEACHER", "STAFF"):
        claim = os.environ.get(f"ROBOTIDE_OIDC_{role}_CLAIM", "")
        if claim and not os.environ.get(f"ROBOTIDE_OIDC_{role}_VALUE"):
            raise ImproperlyConfigured(
                f"ROBOTIDE_OIDC_{role}_VALUE must be set when ROBOTIDE_OIDC_{role}_CLAIM is"
            )
    return {
        "discovery_url": discovery,
        "client_id": os.environ["ROBOTIDE_OIDC_CLIENT_ID"],
        "client_secret": os.environ.get("ROBOTIDE_OIDC_CLIENT_SECRET", ""),  # none: PKCE alone
        "name": os.environ.get("ROBOTIDE_OIDC_NAME") or gettext_lazy("single sign-on"),
        "scopes": scopes,
        "claims": claims,
        "classes_claim": os.environ.get("ROBOTIDE_OIDC_CLASSES_CLAIM", ""),
        "class_pattern": os.environ.get("ROBOTIDE_OIDC_CLASS_PATTERN", ""),
        "teacher": (
            os.environ.get("ROBOTIDE_OIDC_TEACHER_CLAIM", ""),
            os.environ.get("ROBOTIDE_OIDC_TEACHER_VALUE", ""),
        ),
        "staff": (
            os.environ.get("ROBOTIDE_OIDC_STAFF_CLAIM", ""),
            os.environ.get("ROBOTIDE_OIDC_STAFF_VALUE", ""),
        ),
    }


OIDC = oidc_settings()
if OIDC:
    # Called by robotide.oidc's callback alone (no password: the throttle has nothing to count).
    AUTHENTICATION_BACKENDS = [*AUTHENTICATION_BACKENDS, "robotide.oidc.ProviderBackend"]
    # Signing out posts a form that is redirected to the provider's end_session_endpoint, which
    # form-action must allow (browsers check a form's redirects too).
    _provider = urlsplit(OIDC["discovery_url"])
    CONTENT_SECURITY_POLICY["DIRECTIVES"]["form-action"].append(
        f"{_provider.scheme}://{_provider.netloc}"
    )
# The throttle's counters live in the cache: per process by default, shared through Redis in
# fleet mode so every web worker sees the same failures.
if REDIS_URL:
    CACHES = {
        "default": {
            "BACKEND": "django.core.cache.backends.redis.RedisCache",
            "LOCATION": REDIS_URL,
            "KEY_PREFIX": "robotide",
        }
    }
# -- end of Web security --------------------------------------------------------------------------

LANGUAGE_CODE = "en"
TIME_ZONE = os.environ.get("TIME_ZONE", "UTC")
# Pages speak the browser's language (Accept-Language), or the one chosen in the menu, which a
# signed-in user keeps (robotide.language). A language here needs a complete catalog in locale/.
USE_I18N = True
LANGUAGES = [("en", "English"), ("pt-br", "Português (Brasil)")]
LOCALE_PATHS = [BASE_DIR / "locale"]
USE_TZ = True

STATIC_URL = "static/"
STATIC_ROOT = DATA_DIR / "static"
STATIC_ROOT.mkdir(exist_ok=True)
STATICFILES_DIRS = [BASE_DIR / "robotide" / "static"]
STORAGES = {
    "default": {"BACKEND": "django.core.files.storage.FileSystemStorage"},
    "staticfiles": {"BACKEND": "django.contrib.staticfiles.storage.StaticFilesStorage"},
}
if REDIS_URL and not DEBUG:
    # The portal: `robotide up` collects the files once; they are served compressed, with
    # names that change with their content, so browsers keep them for a year.
    STORAGES["staticfiles"]["BACKEND"] = "whitenoise.storage.CompressedManifestStaticFilesStorage"
else:
    # Serve straight from the app folders: no collectstatic step for the one-command appliance.
    WHITENOISE_USE_FINDERS = True
WHITENOISE_AUTOREFRESH = DEBUG

# Limits a run gets unless its robot's settings say otherwise (see runbox.launcher).
RUN_DEFAULTS = {
    "cpu_seconds": env_int("ROBOTIDE_RUN_CPU_SECONDS", 600),
    "wall_seconds": env_int("ROBOTIDE_RUN_WALL_SECONDS", 0),
    "memory_mb": env_int("ROBOTIDE_RUN_MEMORY_MB", 1024),
    "processes": env_int("ROBOTIDE_RUN_PROCESSES", 64),
    "open_files": env_int("ROBOTIDE_RUN_OPEN_FILES", 256),
    "file_size_mb": env_int("ROBOTIDE_RUN_FILE_SIZE_MB", 64),
    "disk_mb": env_int("ROBOTIDE_RUN_DISK_MB", 256),
    "log_size_mb": env_int("ROBOTIDE_RUN_LOG_SIZE_MB", 64),
    "cpu_percent": env_int("ROBOTIDE_RUN_CPU_PERCENT", 100),  # of one CPU, the run as a whole
    # A program printing faster waits in its write (nothing lost): a flood costs the server
    # at most this much reading, splitting and writing lines (runbox.supervisor).
    "output_kb_per_second": env_int("ROBOTIDE_RUN_OUTPUT_KB_PER_SECOND", 256),
    "stop_grace_seconds": 3,
}
# -- Run logs (runlogs): a user's logs together, and everybody's, stay within these (bytes on
# disk; a running run's log counts). When one is met, the oldest ended logs are pruned first:
# the user's own for their quota, anybody's for the total; the runs themselves are kept. 256 MB
# holds four full 64 MB logs a student; the total is 4 GB, or a quarter of the disk holding the
# runs if that is less (a Pi's SD card), so logs can never take the space the database needs.
RUN_LOG_QUOTA_PER_USER = env_int("ROBOTIDE_LOG_QUOTA_PER_USER_MB", 256) * 1024 * 1024
RUN_LOG_QUOTA_TOTAL = env_int("ROBOTIDE_LOG_QUOTA_TOTAL_MB", 0) * 1024 * 1024 or None
# An ended log is compressed (gzip) this long after its run ended: until then a viewer who
# just watched it reads it as it was written.
RUN_LOG_COMPRESS_AFTER = env_float("ROBOTIDE_LOG_COMPRESS_AFTER_SECONDS", 300.0)
# -- A shared robot's run queue (robots.run_queue): while others wait, the program holding the
# robot is stopped after this many seconds; a robot's settings.queue_turn_seconds overrides it
# (0: no limit).
QUEUE_TURN_SECONDS = env_float("ROBOTIDE_QUEUE_TURN_SECONDS", 300.0)
# -- Fair shares (robots.fair_shares): runs one user has going at once, on all robots; more
# wait queued. Staff get their own number; 0: no limit. A robot's settings.runs_at_once caps
# the runs on it, whoever's.
RUNS_PER_USER = env_int("ROBOTIDE_RUNS_PER_USER", 2)
RUNS_PER_STAFF = env_int("ROBOTIDE_RUNS_PER_STAFF", 8)
if RUNS_PER_USER < 0 or RUNS_PER_STAFF < 0:
    raise ValueError("ROBOTIDE_RUNS_PER_USER and ROBOTIDE_RUNS_PER_STAFF must be 0 or more")
# -- Personal sims (robots.sims): simulated robots of one's own, this many a user (0: none)
# and on the whole server; one unused this many minutes is removed (its runs are kept).
SIMS_PER_USER = env_int("ROBOTIDE_SIMS_PER_USER", 2)
SIMS_MAX = env_int("ROBOTIDE_SIMS_MAX", 40)
SIM_IDLE_MINUTES = env_float("ROBOTIDE_SIM_IDLE_MINUTES", 60.0)
if SIMS_PER_USER < 0 or SIMS_MAX < 0 or SIM_IDLE_MINUTES <= 0:
    raise ValueError(
        "ROBOTIDE_SIMS_PER_USER and ROBOTIDE_SIMS_MAX must be 0 or more, and"
        " ROBOTIDE_SIM_IDLE_MINUTES more than 0"
    )
# -- Checking an exercise (classroom.checking, robots.check_sims): each variant's run has a
# fresh sim of its own, at most CHECK_SIMS_MAX of them at once on the server (a Check beyond
# it is refused, saying to try again); of their runs, at most CHECK_RUNS_AT_ONCE go at once
# (robots.fair_shares), the others wait queued, their reason saying so. Default: the CPUs.
# A check sim runs faster than real time, so a reply late on a busy machine is late in the
# sim by the speed's factor: with about a CPU a check run, a result depends little on how
# many classmates press Check at the same moment (docs/classroom.md).
CHECK_SIMS_MAX = env_int("ROBOTIDE_CHECK_SIMS_MAX", 100)
CHECK_RUNS_AT_ONCE = env_int("ROBOTIDE_CHECK_RUNS_AT_ONCE", os.cpu_count() or 1)
if CHECK_SIMS_MAX < 1 or CHECK_RUNS_AT_ONCE < 1:
    raise ValueError("ROBOTIDE_CHECK_SIMS_MAX and ROBOTIDE_CHECK_RUNS_AT_ONCE must be 1 or more")
# -- All runs together (runbox.share): their parent cgroup's memory (a share of the RAM or of
# the server's own cgroup, whichever is smaller), processes, and CPU weight (the server's 100).
RUNS_SHARE = {
    "memory_share": env_float("ROBOTIDE_RUNS_MEMORY_SHARE", 0.6),
    "pids": env_int("ROBOTIDE_RUNS_PIDS", 4096),
    "cpu_weight": env_int("ROBOTIDE_RUNS_CPU_WEIGHT", 50),
}
Share.from_settings(RUNS_SHARE)  # one out of range stops the start, saying which
# -- Program isolation (runbox.isolation): a robot's settings may override each.
RUN_ISOLATION = {
    "isolation": os.environ.get("ROBOTIDE_RUN_ISOLATION", "auto"),
    "network": os.environ.get("ROBOTIDE_RUN_NETWORK", "loopback"),
    "tmp_mb": env_int("ROBOTIDE_RUN_TMP_MB", 64),
    # Host loopback ports relayed into runs ("tcp:9090"), private ranges `full` may reach.
    "loopback_ports": [],
    "allow_networks": [],
}

# -- Fleet mode: an agent says it is alive this often; a robot not heard from for
# AGENT_OFFLINE_AFTER seconds is offline, and the runs it had are lost.
AGENT_HEARTBEAT = env_float("ROBOTIDE_AGENT_HEARTBEAT", 2.0)
AGENT_OFFLINE_AFTER = env_float("ROBOTIDE_AGENT_OFFLINE_AFTER", 7.0)
# A run its online agent has not taken within this long is failed (the request was lost).
AGENT_START_TIMEOUT = 30.0
# What a program showed (bot.show) leaves its robot's page this long after the run ended.
SHOWS_KEEP_SECONDS = env_float("ROBOTIDE_SHOWS_KEEP_SECONDS", 60.0)

# -- MAVLink gateway (robots.gateway): the endpoints a mavlink:// robot starts with.
# Ground stations (QGroundControl, Mission Planner) reach the robot on UDP 14550; programs run
# here get their endpoint's address in ROBOT_MAVLINK.
GATEWAY_DEFAULTS = {
    "gcs": os.environ.get("ROBOTIDE_GATEWAY_GCS", "0.0.0.0:14550"),
    "programs": os.environ.get("ROBOTIDE_GATEWAY_PROGRAMS", "127.0.0.1:14551"),
}

# -- E-mail (programs sent by e-mail: programs.outbound) -------------------------------------------
# Mail is printed to the server's log until EMAIL_HOST names an SMTP server.
EMAIL_HOST = os.environ.get("EMAIL_HOST", "")
EMAIL_PORT = env_int("EMAIL_PORT", 25)
EMAIL_HOST_USER = os.environ.get("EMAIL_HOST_USER", "")
EMAIL_HOST_PASSWORD = os.environ.get("EMAIL_HOST_PASSWORD", "")
EMAIL_USE_TLS = env_bool("EMAIL_USE_TLS", False)  # STARTTLS, usually port 587
EMAIL_USE_SSL = env_bool("EMAIL_USE_SSL", False)  # TLS from the start, usually port 465
if EMAIL_USE_TLS and EMAIL_USE_SSL:
    raise ValueError("EMAIL_USE_TLS and EMAIL_USE_SSL exclude each other: set one")
EMAIL_TIMEOUT = 10  # a mail server that does not answer is an error, not a hung request
EMAIL_BACKEND = (
    "django.core.mail.backends.smtp.EmailBackend"
    if EMAIL_HOST
    else "django.core.mail.backends.console.EmailBackend"
)
DEFAULT_FROM_EMAIL = os.environ.get("DEFAULT_FROM_EMAIL", "robotide@localhost")
# Mails one user may send in an hour, so the appliance cannot be used to spam; 0 turns it off.
EMAIL_PER_HOUR = env_int("ROBOTIDE_EMAIL_PER_HOUR", 20)

# -- Push (programs pushed to another robotide: programs.outbound) ---------------------------------
# Pushes go to public addresses only, and to these networks besides: a lab's own robotides on its
# LAN, e.g. "10.0.5.0/24,192.168.1.20". Checked here, so a typo stops the start, not a push.
PUSH_ALLOW = env_list("ROBOTIDE_PUSH_ALLOW", [])
for _network in PUSH_ALLOW:
    try:
        ipaddress.ip_network(_network, strict=False)
    except ValueError:
        raise ValueError(f"ROBOTIDE_PUSH_ALLOW: {_network!r} is no address or network") from None

# -- Pages (lab rules, robot wiring, exercises: staff edit them in the admin) ---------------------
# django.contrib.flatpages served under /pages/, listed in the menu, sanitised when shown.
INSTALLED_APPS += ["django.contrib.sites", "django.contrib.flatpages"]
SITE_ID = 1
TEMPLATES[0]["OPTIONS"]["context_processors"].append("robotide.context_processors.menu_pages")

LOGGING = {
    "version": 1,
    "disable_existing_loggers": False,
    "formatters": {"plain": {"format": "%(asctime)s %(levelname)s %(name)s: %(message)s"}},
    "handlers": {"console": {"class": "logging.StreamHandler", "formatter": "plain"}},
    "root": {"handlers": ["console"], "level": os.environ.get("LOG_LEVEL", "INFO")},
    "loggers": {"django.channels.server": {"level": "WARNING"}},
}
