"""user_account.session_stamp: a random stamp in every signed-in cookie, renewed when the user is disabled, enabled,
given a new password or another role, so those end every session on every server of the database

Revision ID: 0004_session_stamp
Revises: 0003_accounts
Create Date: 2026-11-25
"""

from __future__ import annotations

import secrets

import sqlalchemy as sa
from alembic import op

revision = "0004_session_stamp"
down_revision = "0003_accounts"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("user_account") as batch:
        batch.add_column(sa.Column("session_stamp", sa.String(32), nullable=False, server_default=""))
    users = sa.table("user_account", sa.column("id", sa.Integer()), sa.column("session_stamp", sa.String(32)))
    connection = op.get_bind()
    for (user_id,) in connection.execute(sa.select(users.c.id)).all():  # existing sign-ins end once
        connection.execute(users.update().where(users.c.id == user_id).values(session_stamp=secrets.token_hex(8)))


def downgrade() -> None:
    with op.batch_alter_table("user_account") as batch:
        batch.drop_column("session_stamp")
