"""Workflows: orchestrate runs, forks, studies and campaigns (no physics of their own).

``pairs``: pair.json of a fork; ``study``: `gouge study`; ``campaign_spec``: the campaign file and
its sweep points; ``campaign``: pieces, ledger, planning and execution; ``executors``: the Dask
clusters that execute the pieces.
"""
