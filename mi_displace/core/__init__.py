"""Shared core: backend, I/O, base surfaces, height fields, tessellation."""
