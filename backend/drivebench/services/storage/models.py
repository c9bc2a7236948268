"""Tables of the DriveBench database. The schema changes only through migrations (``drivebench/migrations``)."""

from __future__ import annotations

import secrets
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column

from drivebench.services.storage.database import Base


def utcnow() -> datetime:
    return datetime.now(UTC)


def new_session_stamp() -> str:
    return secrets.token_hex(8)


class PlannedNetworkRow(Base):
    """A saved network plan; ``body`` is the plan as JSON (``services.planner.NetworkPlan``)."""

    __tablename__ = "planned_network"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(200), nullable=False, index=True)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    updated: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow,
                                              onupdate=utcnow)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)



class LineProjectRow(Base):
    """A line project (migration 0010_line_project): ``body`` is the project file's JSON
    (``services.planning.line_project.LineProject``), ``network_id`` the planned network it made."""

    __tablename__ = "line_project"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(200), nullable=False, index=True)
    network_id: Mapped[int | None] = mapped_column(ForeignKey("planned_network.id", ondelete="SET NULL"),
                                                   nullable=True)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    updated: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow,
                                              onupdate=utcnow)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)

class LineWizardRow(Base):
    """A run of the "New line" wizard (migration 0012_line_wizard): the session and line project it commissions,
    ``body`` its steps' state and results, the devices found and the node each was given
    (``services.line.wizard_run.WizardRun``), so a run resumes after a reload or a server restart."""

    __tablename__ = "line_wizard_run"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    session_id: Mapped[str] = mapped_column(String(120), nullable=False, index=True)
    project_id: Mapped[int | None] = mapped_column(ForeignKey("line_project.id", ondelete="SET NULL"), nullable=True)
    created_by: Mapped[str] = mapped_column(String(120), nullable=False)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    updated: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow,
                                              onupdate=utcnow)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)
    step_claim: Mapped[str | None] = mapped_column(String(32), nullable=True)
    """The claim on the step that runs now (a token of the request that runs it; migration 0014_wizard_step_claim):
    one step of a run at a time across every server of the database (``services.line.wizard_claim``)."""
    step_name: Mapped[str | None] = mapped_column(String(20), nullable=True)
    step_server: Mapped[str | None] = mapped_column(String(120), nullable=True)
    """The server process that holds the claim (host:pid)."""
    step_since: Mapped[float | None] = mapped_column(Float, nullable=True)
    step_lease_until: Mapped[float | None] = mapped_column(Float, nullable=True)
    """The holder renews this while the step runs; once it has passed, the step was cut off (epoch seconds)."""


class CheckedFirmwareRow(Base):
    """A firmware file checked against a node and waiting to be sent (migration 0013_checked_firmware): kept in the
    database so a download, or the wizard's program step, finds it after a server restart and on a second server
    (``services.program.uploads``)."""

    __tablename__ = "checked_firmware"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    session_id: Mapped[str] = mapped_column(String(120), nullable=False)
    node_id: Mapped[int] = mapped_column(Integer, nullable=False)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    name: Mapped[str] = mapped_column(String(300), nullable=False)
    kind: Mapped[str] = mapped_column(String(8), nullable=False)
    image: Mapped[bytes] = mapped_column(LargeBinary, nullable=False)
    start_address: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    identity: Mapped[dict[str, int]] = mapped_column(JSON, nullable=False)


# --- parameter sets, downloads, audit log (migration 0002_parameter_sets) -----------------------------------
class ParameterSetRow(Base):
    """A stored parameter set: what it is for (profile id + version), where it came from, who made it.

    The values live in :class:`ParameterSetVersionRow` (one JSON body per version: a 5,000-parameter set is one
    row to read and one dict to compare, not 5,000 rows)."""

    __tablename__ = "parameter_set"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(200), nullable=False, index=True)
    profile_id: Mapped[str] = mapped_column(String(120), nullable=False, index=True)
    profile_version: Mapped[str] = mapped_column(String(40), nullable=False)
    device: Mapped[str] = mapped_column(String(200), nullable=False)
    node_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    """The node the values were uploaded from (None: imported from a file)."""
    session_id: Mapped[str | None] = mapped_column(String(120), nullable=True)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    updated: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    created_by: Mapped[str] = mapped_column(String(120), nullable=False)
    note: Mapped[str] = mapped_column(Text, nullable=False, default="")
    version: Mapped[int] = mapped_column(Integer, nullable=False, default=1)
    """The current version (the newest row in parameter_set_version)."""


class ParameterSetVersionRow(Base):
    """One version of a set's values: ``body = {"values": {ref: raw}}`` in the profile's order."""

    __tablename__ = "parameter_set_version"
    __table_args__ = (UniqueConstraint("set_id", "version", name="uq_parameter_set_version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    set_id: Mapped[int] = mapped_column(ForeignKey("parameter_set.id", ondelete="CASCADE"), nullable=False,
                                        index=True)
    version: Mapped[int] = mapped_column(Integer, nullable=False)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    created_by: Mapped[str] = mapped_column(String(120), nullable=False)
    reason: Mapped[str] = mapped_column(String(300), nullable=False)
    count: Mapped[int] = mapped_column(Integer, nullable=False)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)


class DownloadRow(Base):
    """One download (or rollback) of values to a node: the values read first (``before``, committed before the
    first write, so a rollback works even after a crash) and the final report per parameter."""

    __tablename__ = "parameter_download"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    kind: Mapped[str] = mapped_column(String(20), nullable=False)
    """``download``, ``retry`` or ``rollback``."""
    set_id: Mapped[int | None] = mapped_column(ForeignKey("parameter_set.id", ondelete="SET NULL"), nullable=True)
    set_version: Mapped[int | None] = mapped_column(Integer, nullable=True)
    session_id: Mapped[str] = mapped_column(String(120), nullable=False)
    node_id: Mapped[int] = mapped_column(Integer, nullable=False)
    profile_id: Mapped[str] = mapped_column(String(120), nullable=False)
    user: Mapped[str] = mapped_column(String(120), nullable=False)
    started: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    finished: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    state: Mapped[str] = mapped_column(String(20), nullable=False)
    """``running`` until the report is stored; a row still ``running`` after its job is gone was interrupted."""
    before: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)
    report: Mapped[list[Any]] = mapped_column(JSON, nullable=False)
    server: Mapped[str | None] = mapped_column(String(120), nullable=True)
    """The server process that runs it (host:pid, 0005_shared_state; None: before that): only it knows whether a
    ``running`` row still has a job behind it."""


class AuditRow(Base):
    """Every write the tool sends to a device: one row before it is sent (result ``sending``), completed after."""

    __tablename__ = "audit_log"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    time: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow, index=True)
    user: Mapped[str] = mapped_column(String(120), nullable=False)
    session_id: Mapped[str] = mapped_column(String(120), nullable=False)
    node_id: Mapped[int] = mapped_column(Integer, nullable=False, index=True)
    ref: Mapped[str] = mapped_column(String(60), nullable=False)
    address: Mapped[str] = mapped_column(String(20), nullable=False)
    old_value: Mapped[str | None] = mapped_column(Text, nullable=True)
    new_value: Mapped[str] = mapped_column(Text, nullable=False)
    result: Mapped[str] = mapped_column(String(20), nullable=False)
    """``sending`` (the tool stopped during the write), ``written``, ``not verified``, ``mismatch``, ``failed``."""
    detail: Mapped[str | None] = mapped_column(Text, nullable=True)
    origin: Mapped[str] = mapped_column(String(60), nullable=False)
    """``parameters`` (a single write), ``download 12``, ``rollback 13``, ``undo 14`` ..."""
    profile: Mapped[str | None] = mapped_column(String(120), nullable=True)
    """The id of the profile the node was handled with (None: no profile, or a row older than migration 0007)."""


# --- users and API tokens (migration 0003_accounts) ------------------------------------------------------------
class UserRow(Base):
    """A person who may sign in: a role and an argon2 hash of the password (never the password)."""

    __tablename__ = "user_account"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(60), nullable=False, unique=True)
    role: Mapped[str] = mapped_column(String(20), nullable=False)
    """``viewer``, ``engineer`` or ``admin`` (``services.principals.Role``)."""
    password_hash: Mapped[str] = mapped_column(String(255), nullable=False)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    disabled: Mapped[bool] = mapped_column(Boolean, nullable=False, default=False)
    session_stamp: Mapped[str] = mapped_column(String(32), nullable=False, default=new_session_stamp)
    """Part of every signed-in cookie; renewed on disable, enable, new password and new role (0004_session_stamp),
    which ends the user's sessions on every server of the database for good."""


class ApiTokenRow(Base):
    """An API token for scripts: only a SHA-256 of the token is stored; the token is shown once when issued."""

    __tablename__ = "api_token"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(120), nullable=False)
    owner_id: Mapped[int] = mapped_column(ForeignKey("user_account.id", ondelete="CASCADE"), nullable=False,
                                          index=True)
    role: Mapped[str] = mapped_column(String(20), nullable=False)
    """Never higher than the owner's role; the lower of the two counts when the owner's role changes."""
    token_hash: Mapped[str] = mapped_column(String(64), nullable=False, unique=True)
    hint: Mapped[str] = mapped_column(String(16), nullable=False)
    """The first characters of the token, so a user can tell tokens apart."""
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    last_used: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    revoked: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    parent_id: Mapped[int | None] = mapped_column(ForeignKey("api_token.id", ondelete="CASCADE"), nullable=True,
                                                  index=True)
    """The token whose request made this one (0006_token_parent; None: made by a signed-in user or the CLI): it
    is refused, and revoked, with its parent."""


# --- state every server of the database shares (migration 0005_shared_state) -----------------------------------
# Times here are seconds since the epoch (``time.time()``): the servers compare them with their own clocks.
class ShareLinkRow(Base):
    """A remote-diagnostics link (``services.sharing``): only a SHA-256 of its token, never the token."""

    __tablename__ = "share_link"

    id: Mapped[str] = mapped_column(String(16), primary_key=True)
    token_hash: Mapped[str] = mapped_column(String(64), nullable=False, unique=True)
    hint: Mapped[str] = mapped_column(String(16), nullable=False)
    label: Mapped[str] = mapped_column(String(80), nullable=False)
    created: Mapped[float] = mapped_column(Float, nullable=False)
    expires: Mapped[float] = mapped_column(Float, nullable=False, index=True)
    shows: Mapped[str] = mapped_column(String(200), nullable=False, server_default="health,faults")
    """What the link shows, comma-separated (``sharing.SHOWS``; 0008_share_link_shows)."""


class SignedOutSessionRow(Base):
    """A cookie session that was signed out, refused until its cookie would have expired anyway."""

    __tablename__ = "signed_out_session"

    sid: Mapped[str] = mapped_column(String(64), primary_key=True)
    until: Mapped[float] = mapped_column(Float, nullable=False, index=True)


class SignInFailureRow(Base):
    """Failed sign-ins of one key (``user:anna``, ``address:10.0.0.9``) and the lock they earned."""

    __tablename__ = "sign_in_failure"

    key: Mapped[str] = mapped_column(String(300), primary_key=True)
    count: Mapped[int] = mapped_column(Integer, nullable=False)
    locked_until: Mapped[float] = mapped_column(Float, nullable=False)
    last: Mapped[float] = mapped_column(Float, nullable=False, index=True)


# --- scope: what a PDO recording changed on the nodes (migration 0009_scope_restore) ----------------------------
class ScopeRestoreRow(Base):
    """Written before a recording changes a node's PDO or SYNC setting, removed after a good read-back of the
    restore; a row left over (the server was killed mid-recording) is restored on the next start.
    ``body``: the nodes' values before (``services.scope.restore_record.RestoreRecord``)."""

    __tablename__ = "scope_restore"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    bus: Mapped[str] = mapped_column(String(200), nullable=False)
    server: Mapped[str] = mapped_column(String(120), nullable=False)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)


# --- scope recordings (migration 0011_scope_recordings) -----------------------------------------------------------
class ScopeRecordingRow(Base):
    """A stored scope recording. ``samples`` is packed (``services.scope.store``): the sample numbers (int64), the
    times and each channel's values (float64, NaN where the node sent nothing), one array after the other: 8
    channels x 100,000 samples are one 7 MB value, written and read in one piece."""

    __tablename__ = "scope_recording"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(200), nullable=False)
    session_id: Mapped[str] = mapped_column(String(120), nullable=False)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow, index=True)
    created_by: Mapped[str] = mapped_column(String(120), nullable=False)
    source: Mapped[str] = mapped_column(String(20), nullable=False)
    """``pdo``, ``sdo-poll`` or ``coe-poll``."""
    period_s: Mapped[float] = mapped_column(Float, nullable=False)
    """The period the source really reached."""
    channels: Mapped[list[Any]] = mapped_column(JSON, nullable=False)
    trigger: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)
    """The trigger settings and the trigger sample's position (``position``, None: free run)."""
    markers: Mapped[list[Any]] = mapped_column(JSON, nullable=False)
    nodes: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)
    """Per node: the profile (id, version), the device and the parameter set last downloaded to it."""
    count: Mapped[int] = mapped_column(Integer, nullable=False)
    samples: Mapped[bytes] = mapped_column(LargeBinary, nullable=False)
