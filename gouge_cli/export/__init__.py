"""Exports of run files to the formats of other tools (read run files only)."""
