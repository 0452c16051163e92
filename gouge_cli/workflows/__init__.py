"""Orchestration over runs, forks and analysis (owns no physics): pair.json, `gouge study`."""
