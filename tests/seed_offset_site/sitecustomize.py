"""Imported at start-up by every Python process the test suite starts while GOUGE_TEST_SEED_OFFSET
is set (conftest puts this folder on PYTHONPATH): gouge subprocesses, process-pool workers of
`gouge study`, Dask workers. It applies the same seed shift there (tests/seed_offset.py)."""

import os
import sys

if os.environ.get("GOUGE_TEST_SEED_OFFSET", "0") not in ("", "0"):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        import seed_offset
        seed_offset.install()
    except ImportError:          # gouge not importable in this interpreter: nothing to shift
        pass
