"""Evaluation: image and mesh metrics, the comparison protocol, figures."""
