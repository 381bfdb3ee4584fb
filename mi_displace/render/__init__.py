"""Rendering: the GPU-style raster integrator and scene loading/rendering helpers."""
