"""The database: engine, migrations' entry, tables."""
