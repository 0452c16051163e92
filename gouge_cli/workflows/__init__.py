"""Workflows: orchestrate runs and forks (no physics of their own).

``campaign_spec``: the campaign file and its sweep points; ``campaign``: pieces, ledger,
planning and execution; ``executors``: the Dask clusters that execute the pieces.
"""
