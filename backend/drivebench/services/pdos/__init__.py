"""PDO configuration and live process data."""
