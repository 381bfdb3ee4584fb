"""Tests written to kill mutants of the ddm/ modules that survived the other tests
(issue 19, docs/testing.md, "Remaining ddm/ and core/ modules")."""
from __future__ import annotations
