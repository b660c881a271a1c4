"""Subcommands (to be filled in)."""
