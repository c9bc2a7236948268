"""Settings, read once from the environment (prefix ``DRIVEBENCH_``)."""

from __future__ import annotations

from pathlib import Path

from pydantic_settings import BaseSettings, SettingsConfigDict

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
    sdo_timeout_s: float = 0.5
    sdo_retries: int = 1
    max_upload_bytes: int = 5 * 1024 * 1024


settings = Settings()
