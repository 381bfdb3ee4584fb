"""VDM: view-dependent displacement mapping (paper 001)."""
