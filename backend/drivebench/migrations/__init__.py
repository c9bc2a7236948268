"""Alembic migrations of the DriveBench database (run by ``services.database.upgrade_to_head``)."""
