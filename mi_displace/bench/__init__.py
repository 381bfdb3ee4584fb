"""Benchmarks (`mi-displace bench NAME`): warm timings with ratios against baselines
measured in the same process (Mitsuba's own acceleration build and path tracer)."""
