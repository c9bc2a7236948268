"""A whole line: the line project file, its store, the boot-up check against it (issue 32)."""
