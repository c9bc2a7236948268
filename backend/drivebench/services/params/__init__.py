"""A node's parameters: read and write by name or index, write leases, read-all jobs."""
