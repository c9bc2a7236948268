"""Byte-level examples from the device manuals, shared by tests at every layer."""
