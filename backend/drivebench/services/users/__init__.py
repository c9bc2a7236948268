"""Users, roles, API tokens, share links and the audit log."""
