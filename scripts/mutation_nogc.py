"""pytest plugin of scripts/mutation.sh: no full garbage collection between tests.

tests/conftest.py collects each test's garbage before the next (a scene's Python plugin
objects kept alive by reference cycles could otherwise be reached by a later scene); that
full collection took two thirds of the run time of the mutation selections, which build
no such scenes.  Python's automatic (generational) collection still runs.
"""
import gc

gc.collect = lambda generation=2: 0
