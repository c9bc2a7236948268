"""Settings, read once from the environment (prefix ``DRIVEBENCH_``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import SecretStr, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict
from sqlalchemy.engine import make_url

REPO_ROOT = Path(__file__).resolve().parents[2]


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="DRIVEBENCH_")

    host: str = "127.0.0.1"
    port: int = 8000
    profiles_dir: Path = REPO_ROOT / "device_profiles"
    user_profiles_dir: Path = REPO_ROOT / "var" / "profiles"
    plants_dir: Path = REPO_ROOT / "plants"
    frontend_dir: Path = REPO_ROOT / "frontend"
    database_url: str = f"sqlite:///{REPO_ROOT / 'var' / 'drivebench.db'}"
    database_password_file: Path | None = None
    """The database password from a file (a container secret) rather than inside ``database_url``, where ``docker
    inspect`` would show it: it replaces the URL's password."""
    database_wait_s: float = 30.0
    """``drivebench serve`` waits this long for an unreachable database (a container started with its database),
    then exits saying what failed."""
    sdo_timeout_s: float = 0.5
    sdo_retries: int = 1
    max_upload_bytes: int = 5 * 1024 * 1024
    max_batch_upload_bytes: int = 64 * 1024 * 1024
    """Many files or a zip at once (``/api/profiles/batch``): each file inside still has ``max_upload_bytes``."""
    secret_key: str | None = None
    """Signs the sign-in cookies; without it a random key is made once and kept in ``secret_key_file`` (0600)."""
    secret_key_file: Path = REPO_ROOT / "var" / "secret_key"
    session_max_age_s: int = 12 * 3600
    """A sign-in lasts this long (a working day), then the browser asks again."""
    admin_user: str = "admin"
    admin_password: SecretStr | None = None
    admin_password_file: Path | None = None
    """The first admin, made when ``drivebench serve`` starts on a database without users (a container's first
    start): the password from ``DRIVEBENCH_ADMIN_PASSWORD`` or, better, a secret file. Never printed."""
    tls_cert_file: Path | None = None
    tls_key_file: Path | None = None
    hsts: bool = False
    """Send Strict-Transport-Security over https (off by default: a browser then refuses plain http to the name
    for a year, which locks a plant out if the certificate is ever removed)."""
    allowed_hosts: Annotated[list[str], NoDecode] = []
    """Host names (besides 127.0.0.1, localhost and [::1]) under which browsers reach the server, e.g. behind a
    reverse proxy or by the machine's name; ``DRIVEBENCH_ALLOWED_HOSTS=a.example,b.example``. Any other ``Host`` or
    ``Origin`` is refused (DNS rebinding)."""
    public_url: str | None = None
    """Where others reach this server (``https://drivebench.plant.example``): share links are built from it, else
    from the address the server listens on, never from a request's ``Host`` header."""
    api_docs: bool = False
    """Serve FastAPI's /docs and /redoc pages (``DRIVEBENCH_API_DOCS=1``, for development): they load their scripts
    from a CDN, so a production server leaves them off. /openapi.json is always served."""
    forwarded_allow_ips: str | None = None
    root_path: str = ""
    """The sub-path a reverse proxy serves DriveBench under (``/drivebench``; ``DRIVEBENCH_ROOT_PATH``): the proxy
    strips it, uvicorn's ``root_path`` puts it back in front of every link, redirect and cookie path."""
    """Proxies whose ``X-Forwarded-For`` / ``-Proto`` are believed (uvicorn's option, comma-separated addresses or
    networks); none by default, so a client cannot choose the address the sign-in limit counts."""

    metrics_token_file: Path | None = None
    """A file holding the token a Prometheus scraper sends (``Authorization: Bearer ...``) to read /metrics without
    signing in; it grants nothing else. Without it, /metrics needs the engineer role."""
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
    """The server log's level (``info``: start, sign-in failures, one access line per request)."""
    log_format: Literal["text", "json"] = "text"
    """``json``: one JSON object per line (time, level, logger, request_id, message) for a log collector."""

    wizard_step_lease_s: float = 30.0
    """A "New line" wizard step's claim lasts this long unless its server renews it (every third of it while the step
    runs): a server that stopped (killed, frozen, cut off) leaves the step ``interrupted`` on the others after that."""

    control_panels_per_node: int = 100
    """Control-panel websockets one node of a session accepts at once (its holder's own panel always)."""
    control_panels_per_user: int = 20
    """Control-panel websockets one user may have open in a session at once."""

    @model_validator(mode="after")
    def _password_from_file(self) -> Settings:
        if self.database_password_file is None:
            return self
        path = self.database_password_file
        try:
            password = path.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) else "it is not UTF-8 text"
            raise ValueError(f"DRIVEBENCH_DATABASE_PASSWORD_FILE {path}: cannot read it ({reason}); give the file "
                             f"holding the database password, readable by this user") from None
        if not password:
            raise ValueError(f"DRIVEBENCH_DATABASE_PASSWORD_FILE {path} is empty: write the database password into it")
        url = make_url(self.database_url).set(password=password)
        self.database_url = url.render_as_string(hide_password=False)
        return self

    @field_validator("allowed_hosts", mode="before")
    @classmethod
    def _split_names(cls, value: object) -> object:
        return [name.strip() for name in value.split(",") if name.strip()] if isinstance(value, str) else value


def _read_settings() -> Settings:
    try:
        return Settings()
    except ValidationError as exc:  # a start-up setting in words, not a traceback
        problems = "; ".join(f"{'.'.join(map(str, error['loc'])) or 'settings'}: {error['msg']}"
                             for error in exc.errors())
        raise SystemExit(f"DriveBench cannot start: {problems}") from None


settings = _read_settings()
