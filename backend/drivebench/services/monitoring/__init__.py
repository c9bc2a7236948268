"""What the bus does: telegram counters, bus load, recordings, node diagnostics (EMCY, heartbeat)."""
