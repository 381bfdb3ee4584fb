"""HDDM: deformation-displacement tiling of arbitrary geometry over a base surface (paper 000)."""
