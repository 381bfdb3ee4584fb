"""Tests written for mutants of slicing/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth."""
