"""Inverse displacement (issue 14): height maps recovered from images by differentiable rendering."""
