"""Plain functions behind the entry scripts in scripts/ (tests call them directly)."""
